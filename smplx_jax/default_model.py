"""The license-free default body model: a human-shaped model in the official SMPL-X file layout, generated
deterministically by code (numpy only, about a second), so that every code path and the PyTorch ``smplx``
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

from smplx_jax.io import atomic_path

GENERATOR_VERSION = 1
_SOURCES = ("assemble.py", "body.py", "cage.py", "hands.py", "head.py", "rig.py", "skeleton.py", "subdiv.py",
            "surface.py")


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


def generator_id() -> str:
    """Version and source hash of the generator: a new generator gets a new cache folder."""
    h = hashlib.sha256()
    folder = Path(__file__).parent / "_default"
    for name in _SOURCES:
        h.update((folder / name).read_bytes())
    return f"v{GENERATOR_VERSION}-{h.hexdigest()[:10]}"


def cache_root() -> Path:
    env = os.environ.get("JAXMOCAP_CACHE")
    return Path(env) if env else Path.home() / ".cache" / "jaxmocap"


def default_model_path() -> Path:
    """Path of ``SMPLX_NEUTRAL.npz`` of the default model, generated on first use and cached under
    ``$JAXMOCAP_CACHE`` (or ``~/.cache/jaxmocap``) in ``default_model/<generator id>/smplx/``; the folder two
    levels up is what ``smplx.create(folder, model_type="smplx")`` takes."""
    path = cache_root() / "default_model" / generator_id() / "smplx" / "SMPLX_NEUTRAL.npz"
    if not path.is_file():
        write_default_model(path)
    return path
