"""Atomic writes: the target is replaced whole or not at all, and no temporary file stays behind."""

import numpy as np
import pytest

from smplx_jax.io import atomic_path, atomic_write_bytes, atomic_write_text


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
