"""``jaxmocap export``: a motion file (or a hands file) to BVH or glTF."""

import sys
import zipfile
from pathlib import Path

import smplx_jax
from jaxmocap.errors import InputError
from jaxmocap.export.animation import animation
from jaxmocap.export.bvh import write_bvh
from jaxmocap.export.gltf import write_gltf
from jaxmocap.export.hands_gltf import write_hands_gltf
from jaxmocap.hand_motion import read_hands
from jaxmocap.motion import read_motion
from jaxmocap.result_files import file_sha256


def is_hands_file(path) -> bool:
    """Whether ``path`` is a ``hands.npz`` (by its keys); anything else is read as a motion."""
    try:
        with zipfile.ZipFile(path) as archive:
            return "left_valid.npy" in archive.namelist()
    except (OSError, zipfile.BadZipFile):
        return False


def _model_path(source, recorded: str, model_path) -> Path:
    """The body model file ``source`` was made with: ``model_path``, or the default model when None (an error
    unless its sha256 is the one ``source`` recorded)."""
    path = smplx_jax.model_path(model_path)
    if recorded and recorded != file_sha256(path):
        message = f"{source} was made with another body model file (sha256 {recorded[:12]}…) than {path}"
        if model_path is None:
            raise InputError(message + "; pass that file with --model")
        print(f"warning: {message}", file=sys.stderr)
    return path


def export_motion(motion_path, fmt: str, out, model_path=None, focal_px: float | None = None,
                  frame: str = "world") -> Path:
    """Write ``out`` in ``fmt`` (``bvh`` or ``gltf``) from a motion file, or a hands file (glTF only), and its body
    model (default model when ``model_path`` is None; it must be the file the motion was made with); a motion in
    its world ``frame`` where it has one, or the camera's (`animation`)."""
    if fmt not in ("bvh", "gltf"):
        raise InputError(f"unknown export format {fmt!r} (bvh or gltf)")
    if is_hands_file(motion_path):
        hands = read_hands(motion_path)
        if fmt == "bvh":
            raise InputError(f"{motion_path} is a hands file: BVH holds one skeleton, export the hands as gltf")
        if not (hands["left_valid"].any() or hands["right_valid"].any()):
            raise InputError(f"{motion_path} holds no valid frame of either hand to export")
        model = smplx_jax.load_model(_model_path(motion_path, str(hands["model_sha256"]), model_path))
        return write_hands_gltf(out, model, hands, focal_px)
    motion = read_motion(motion_path)
    if not motion["valid"].any():
        raise InputError(f"{motion_path} holds no valid frame to export")
    path = _model_path(motion_path, str(motion.get("model_sha256", "")), model_path)
    model = smplx_jax.load_model(path, num_betas=motion["betas"].shape[1])
    anim = animation(model, motion, focal_px, frame)
    return write_bvh(out, anim) if fmt == "bvh" else write_gltf(out, model, anim)
