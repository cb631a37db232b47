"""The license-free default body model: a human-shaped model in the official SMPL-X file layout, generated
deterministically by code (numpy only, cached after the first use), so that every code path and the PyTorch ``smplx``
package run without the licensed SMPL-X files.

    path = default_model_path()                    # .../default_model/v1-<hash>/smplx/SMPLX_NEUTRAL.npz
    smplx.create(str(path.parent.parent), model_type="smplx")

The body is a T-posed adult of about 1.69 m in SMPL-X's frame (y up, facing +z, the body's left at +x,
metres) with SMPL-X's 55 joints, 10475 vertices and the vertex ids ``smplx`` reads as extra joints at the
right places. It is built by box-modelling a quad cage in code, Catmull-Clark subdivision fitted through the
cage's target points, and a sculpted head; see ``smplx_jax/_default``. Shape space: 11 anatomical directions
(PCA of a synthetic population) in ``shapedirs[..., :11]``; expressions in ``shapedirs[..., 300:310]``;
pose corrections (``posedirs``) are zero.
"""

import hashlib
import os
from pathlib import Path

import numpy as np

from smplx_jax.atomic_files import atomic_path

GENERATOR_VERSION = 1
_GENERATOR_DIR = Path(__file__).parent / "_default"
_SHARED_SOURCES = (Path(__file__).parent / "geometry.py",)  # modules outside _default that the generator uses


def build_default_model() -> dict[str, np.ndarray]:
    """The arrays of an SMPL-X ``.npz`` (official keys, shapes and dtypes) for the default body."""
    from smplx_jax._default.assemble import build

    return build()[0]


def write_default_model(path) -> Path:
    """Write the default model to ``path`` (``.npz``), atomically."""
    arrays = build_default_model()
    with atomic_path(path) as tmp:
        np.savez_compressed(tmp, **arrays)
    return Path(path)


def _generator_files(folder: Path) -> list[Path]:
    """Every file of the generator's folder (code and any data, subfolders included), sorted; Python's
    byte-code caches left out."""
    return sorted(p for p in folder.rglob("*")
                  if p.is_file() and "__pycache__" not in p.parts and p.suffix not in (".pyc", ".pyo"))


def generator_id() -> str:
    """Version and hash of every file of ``smplx_jax/_default`` and the shared modules it uses (names and
    contents): editing, adding, removing or renaming any of them gives a new cache folder."""
    h = hashlib.sha256()
    files = [(p.relative_to(_GENERATOR_DIR).as_posix(), p) for p in _generator_files(_GENERATOR_DIR)]
    for name, path in files + [(f"../{p.name}", p) for p in _SHARED_SOURCES]:
        name, data = name.encode(), path.read_bytes()
        h.update(len(name).to_bytes(8, "little") + name + len(data).to_bytes(8, "little") + data)
    return f"v{GENERATOR_VERSION}-{h.hexdigest()[:10]}"


def cache_root() -> Path:
    """Where jaxmocap keeps what it makes or fetches once (``$JAXMOCAP_CACHE``, default
    ``~/.cache/jaxmocap``)."""
    env = os.environ.get("JAXMOCAP_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "jaxmocap"


def private_folder(path: Path) -> Path:
    """``path``, made where missing (with its missing parents) readable and writable by this user alone (0700)."""
    path = Path(path)
    for folder in reversed([p for p in (path, *path.parents) if not p.exists()]):
        folder.mkdir(mode=0o700, exist_ok=True)
    return path


def open_to_others(path: Path) -> bool:
    """Whether another user could change what ``path`` holds: it is not this user's, or a group or others may write
    it (False where it does not exist)."""
    try:
        status = Path(path).stat()
    except OSError:
        return False
    return status.st_uid != os.getuid() or bool(status.st_mode & 0o022)


def model_path(given=None) -> Path:
    """The body model file ``given`` (a path), or the default model's (`default_model_path`) where None."""
    return Path(given) if given else default_model_path()


def default_model_path() -> Path:
    """Path of ``SMPLX_NEUTRAL.npz`` of the default model, generated on first use and cached under
    ``$JAXMOCAP_CACHE`` (or ``~/.cache/jaxmocap``) in ``default_model/<generator id>/smplx/``; the folder two
    levels up is what ``smplx.create(folder, model_type="smplx")`` takes."""
    path = cache_root() / "default_model" / generator_id() / "smplx" / "SMPLX_NEUTRAL.npz"
    if not path.is_file():
        private_folder(cache_root())
        write_default_model(path)
    return path
