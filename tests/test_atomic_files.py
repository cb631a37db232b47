"""Atomic writes: the target is replaced whole or not at all, and no temporary file stays behind (one a killed
writer left is cleared by the next run)."""

import socket
import subprocess
import sys
import textwrap

import numpy as np
import pytest

from smplx_jax.atomic_files import atomic_path, atomic_write_bytes, atomic_write_text, remove_abandoned


def test_a_write_replaces_the_file_readable_by_others(tmp_path):
    path = atomic_write_text(tmp_path / "sub" / "a.txt", "old")
    atomic_write_bytes(path, b"new")
    assert path.read_bytes() == b"new"
    assert path.stat().st_mode & 0o777 == 0o644
    assert list(path.parent.iterdir()) == [path]


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temporary_file(tmp_path):
    path = atomic_write_text(tmp_path / "a.npz", "old")
    with pytest.raises(RuntimeError, match="disk full"):
        with atomic_path(path) as tmp:
            assert tmp.parent == tmp_path and tmp.suffix == ".npz"
            np.savez(tmp, x=np.zeros(3))
            raise RuntimeError("disk full")
    with pytest.raises(TypeError):
        atomic_write_bytes(path, "not bytes")
    assert path.read_text() == "old"
    assert list(tmp_path.iterdir()) == [path]


def test_a_killed_writers_temporary_file_is_removed_and_a_live_ones_kept(tmp_path):
    """SIGKILL inside the write leaves the temporary file; `remove_abandoned` removes it (a dead writer of this
    machine), not a live process's nor another machine's."""
    target = tmp_path / "people" / "0" / "motion.npz"
    writer = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import time
        from smplx_jax.atomic_files import atomic_path
        with atomic_path({str(target)!r}) as tmp:
            tmp.write_bytes(b"half")
            print("writing", flush=True)
            time.sleep(60)
        """)], stdout=subprocess.PIPE, text=True)
    assert writer.stdout.readline().strip() == "writing"
    (abandoned,) = target.parent.iterdir()
    with atomic_path(tmp_path / "live.txt") as live:
        live.write_text("mine")
        elsewhere = tmp_path / live.name.replace(socket.gethostname().replace(".", "-"), "other-host")
        elsewhere.write_text("theirs")
        assert remove_abandoned(tmp_path) == []  # its writer still runs
        writer.kill()
        writer.wait()
        assert remove_abandoned(tmp_path) == [abandoned]
        assert live.exists() and elsewhere.exists() and not abandoned.exists()
    assert remove_abandoned(tmp_path) == [] and elsewhere.exists()
