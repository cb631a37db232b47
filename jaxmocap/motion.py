"""``motion.npz``: one tracked person over ``T`` frames (docs/formats.md, "motion.npz"), checked on write and on read.

With ``X = smplx_forward(params).joints`` (``transl`` included) the pixel of a joint in frame ``t`` is
``camera_scale[t] * X[..., :2] + camera_trans[t]`` (x right, y down). Hand poses are absolute.

A motion fitted through a pinhole camera (the default pipeline) also holds ``focal_length ()`` and
``principal_point (2,)`` in pixels: then ``X`` is in the camera's frame (metres; ``transl`` places the body), its
exact pixels are ``focal_length * X[..., :2] / X[..., 2:] + principal_point``, ``reprojection_error_px`` is theirs,
and ``camera_scale``, ``camera_trans`` are the weak-perspective projection closest to them (`lens`).

A motion whose keypoints came from the detector also holds ``landmark_model ()``, the BlazePose landmark model it
ran (``heavy``, ``full`` or ``lite``).
"""

from pathlib import Path

import numpy as np

import smplx_jax
from jaxmocap.errors import InputError
from jaxmocap.result_files import read_result_npz, write_result_npz

# key -> shape after the frame axis ("B": num_betas), or None for a scalar
MOTION_SHAPES = {
    "global_orient": (3,), "body_pose": (21, 3), "left_hand_pose": (15, 3), "right_hand_pose": (15, 3),
    "jaw_pose": (3,), "betas": ("B",), "transl": (3,), "camera_scale": (), "camera_trans": (2,), "valid": (),
    "keypoints_2d": (67, 3), "reprojection_error_px": (), "fps": None, "image_size": None, "model_sha256": None,
}
PINHOLE_SHAPES = {"focal_length": (), "principal_point": (2,)}  # both or neither
# the world frame (`jaxmocap.integrate.ground`): all or none; key -> shape after the frame axis, or None: no frame axis
WORLD_SHAPES = {"world_global_orient": (3,), "world_transl": (3,), "camera_from_world": (4, 4), "contact": (4,),
                "floor": None}


def lens(motion: dict) -> tuple[float | None, np.ndarray | None]:
    """``(focal_length, principal_point)`` of a motion fitted through a pinhole camera, else ``(None, None)``."""
    if "focal_length" not in motion:
        return None, None
    return float(motion["focal_length"]), np.asarray(motion["principal_point"], np.float64)


def _check(motion: dict, where: str) -> None:
    missing = [k for k in MOTION_SHAPES if k not in motion]
    if missing:
        raise InputError(f"{where} lacks the motion key(s) {', '.join(missing)}; is it a jaxmocap motion.npz?")
    frames = len(np.asarray(motion["valid"]))
    num_betas = np.shape(motion["betas"])[-1] if np.ndim(motion["betas"]) == 2 else -1
    for key, shape in MOTION_SHAPES.items():
        actual = np.shape(motion[key])
        expected = (2,) if key == "image_size" else () if shape is None else (frames,) + tuple(
            num_betas if s == "B" else s for s in shape)
        if actual != expected:
            raise InputError(f"{where}: key {key!r} has shape {actual}, expected {expected}")
    present = [k for k in PINHOLE_SHAPES if k in motion]
    if present and len(present) != len(PINHOLE_SHAPES):
        raise InputError(f"{where}: {present[0]!r} without {({*PINHOLE_SHAPES} - {*present}).pop()!r}")
    for key in present:
        if np.shape(motion[key]) != PINHOLE_SHAPES[key]:
            raise InputError(f"{where}: key {key!r} has shape {np.shape(motion[key])}, expected {PINHOLE_SHAPES[key]}")
    if present and not float(motion["focal_length"]) > 0:
        raise InputError(f"{where}: focal_length must be positive, got {float(motion['focal_length'])}")
    world = [k for k in WORLD_SHAPES if k in motion]
    if world and len(world) != len(WORLD_SHAPES):
        raise InputError(f"{where}: {world[0]!r} without {sorted({*WORLD_SHAPES} - {*world})[0]!r}")
    for key in world:
        expected = (4,) if WORLD_SHAPES[key] is None else (frames, *WORLD_SHAPES[key])
        if np.shape(motion[key]) != expected:
            raise InputError(f"{where}: key {key!r} has shape {np.shape(motion[key])}, expected {expected}")


def write_motion(path, motion: dict) -> Path:
    """Check the arrays and write them atomically as ``.npz`` (float32 parameters)."""
    _check(motion, str(path))
    return write_result_npz(path, motion, ("valid", "contact"))


def read_motion(path) -> dict[str, np.ndarray]:
    """The arrays of a ``motion.npz``, or `InputError` naming the problem."""
    motion = read_result_npz(path, "motion")
    _check(motion, str(path))
    return motion


def motion_params(motion: dict, num_expression: int = 10, frames=slice(None)) -> smplx_jax.SMPLXParams:
    """The motion's bodies (``frames`` of them) as batched `smplx_jax.SMPLXParams`; eyes at rest, no expression
    (motion.npz keeps neither)."""
    def f(k):
        return np.asarray(motion[k][frames], np.float32)
    t = len(f("valid"))
    zeros = np.zeros((t, 3), np.float32)
    return smplx_jax.SMPLXParams(f("global_orient"), f("body_pose"), f("left_hand_pose"), f("right_hand_pose"),
                                 f("jaw_pose"), zeros, zeros, f("betas"), np.zeros((t, num_expression), np.float32),
                                 f("transl"))
