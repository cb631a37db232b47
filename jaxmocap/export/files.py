"""``jaxmocap export``: a motion file to BVH or glTF."""

import sys
from pathlib import Path

import smplx_jax
from jaxmocap.errors import InputError
from jaxmocap.export.animation import animation
from jaxmocap.export.bvh import write_bvh
from jaxmocap.export.gltf import write_gltf
from jaxmocap.io import file_sha256
from jaxmocap.motion import read_motion


def export_motion(motion_path, fmt: str, out, model_path=None, focal_px: float | None = None) -> Path:
    """Write ``out`` in ``fmt`` (``bvh`` or ``gltf``) from a motion file and its body model (default model when
    ``model_path`` is None; it must be the file the motion was made with)."""
    motion = read_motion(motion_path)
    if not motion["valid"].any():
        raise InputError(f"{motion_path} holds no valid frame to export")
    path = Path(model_path) if model_path else smplx_jax.default_model_path()
    recorded = str(motion.get("model_sha256", ""))
    if recorded and recorded != file_sha256(path):
        message = f"{motion_path} was made with another body model file (sha256 {recorded[:12]}…) than {path}"
        if model_path is None:
            raise InputError(message + "; pass that file with --model")
        print(f"warning: {message}", file=sys.stderr)
    num_betas = motion["betas"].shape[1]
    model = smplx_jax.load_model(path, num_betas=num_betas)
    anim = animation(model, motion, focal_px)
    if fmt == "bvh":
        return write_bvh(out, anim)
    if fmt == "gltf":
        return write_gltf(out, model, anim)
    raise InputError(f"unknown export format {fmt!r} (bvh or gltf)")
