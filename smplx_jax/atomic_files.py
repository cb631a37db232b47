"""Atomic file writes: a temporary file beside the target, then ``os.replace``; a failed write leaves the old file
(or none) and no temporary file behind. A writer killed outright (SIGKILL, power loss) can leave its temporary file:
its name says which process of which machine wrote it, and `remove_abandoned` clears those of processes gone."""

import contextlib
import os
import re
import socket
import tempfile
from collections.abc import Iterator
from pathlib import Path

# ``.<stem>.<host>-<pid>.<random>.tmp<suffix>``: the host with its dots as dashes
_TEMPORARY = re.compile(r"\..*\.(?P<host>[^.]+)-(?P<pid>\d+)\.[^.]+\.tmp(\.[^.]*)?")


def _host() -> str:
    return socket.gethostname().replace(".", "-") or "host"


@contextlib.contextmanager
def atomic_path(path) -> Iterator[Path]:
    """A temporary path beside ``path`` (same suffix, for writers that need a file name: ``np.savez``,
    ``cv2.imwrite``) that replaces ``path`` when the block succeeds and is removed when it raises."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, name = tempfile.mkstemp(prefix=f".{path.stem}.{_host()}-{os.getpid()}.", suffix=f".tmp{path.suffix}",
                                dir=path.parent)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.chmod(tmp, 0o644)  # mkstemp's 0600 would hide outputs from other users
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def atomic_write_bytes(path, data: bytes) -> Path:
    """``data`` written to ``path`` atomically (`atomic_path`); returns the path."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)
    return Path(path)


def atomic_write_text(path, text: str) -> Path:
    """``text`` written to ``path`` atomically as UTF-8 (`atomic_write_bytes`); returns the path."""
    return atomic_write_bytes(path, text.encode())


def remove_abandoned(folder, depth: int = 2) -> list[Path]:
    """Remove the temporary files of atomic writes in ``folder`` and its subfolders ``depth`` deep whose writer, a
    process of this machine, is gone; those of live processes and of other machines stay. The paths removed."""
    host, removed = _host(), []
    for level in range(depth + 1):
        for path in Path(folder).glob("/".join(["*"] * level + [".*.tmp*"])):
            match = _TEMPORARY.fullmatch(path.name)
            if match and match["host"] == host and not _alive(int(match["pid"])) and path.is_file():
                path.unlink(missing_ok=True)
                removed.append(path)
    return removed


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's
        pass
    return True
