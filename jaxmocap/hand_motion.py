"""``hands.npz``: both hands over ``T`` frames, without a body (``jaxmocap run --mode hands``; docs/formats.md).

Per side, keys prefixed ``left_`` / ``right_``: ``global_orient (T,3)`` (the wrist's rotation in the image-aligned
camera frame), ``hand_pose (T,15,3)`` (absolute, SMPL-X's finger joints), ``camera_scale (T,)``,
``camera_trans (T,2)``, ``valid (T,)``, ``keypoints_2d (T,21,3)`` (OpenPose hand order, pixels, confidence: the
fit's targets) and ``reprojection_error_px (T,)``; then ``fps``, ``image_size`` and ``model_sha256``. With
``X = hand_forward(hand_model(model, side), R(global_orient), hand_pose, 0).joints`` (the wrist at the origin, the
body model's mean shape) a hand joint lands at pixel ``camera_scale * X[..., :2] + camera_trans``.
"""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import smplx_jax
from jaxmocap.buckets import map_in_buckets
from jaxmocap.errors import InputError
from jaxmocap.result_files import read_result_npz, write_result_npz
from smplx_jax import SIDES
from smplx_jax.rotations import rotvec_to_rotmat

HAND_SHAPES = {"global_orient": (3,), "hand_pose": (15, 3), "camera_scale": (), "camera_trans": (2,), "valid": (),
               "keypoints_2d": (21, 3), "reprojection_error_px": ()}  # after the frame axis
META = ("fps", "image_size", "model_sha256")
BUCKETS = (8, 64)  # padded batch sizes (few: each compiles once)


def _check(hands: dict, where: str) -> None:
    keys = [f"{side}_{k}" for side in SIDES for k in HAND_SHAPES] + list(META)
    missing = [k for k in keys if k not in hands]
    if missing:
        raise InputError(f"{where} lacks the key(s) {', '.join(missing)}; is it a jaxmocap hands.npz?")
    frames = len(np.asarray(hands["left_valid"]))
    for side in SIDES:
        for key, shape in HAND_SHAPES.items():
            actual, expected = np.shape(hands[f"{side}_{key}"]), (frames,) + shape
            if actual != expected:
                raise InputError(f"{where}: key {side}_{key!r} has shape {actual}, expected {expected}")
    if np.shape(hands["image_size"]) != (2,):
        raise InputError(f"{where}: key 'image_size' has shape {np.shape(hands['image_size'])}, expected (2,)")


def write_hands(path, hands: dict) -> Path:
    """Check the arrays and write them atomically as ``.npz`` (float32 values, bool ``valid``)."""
    _check(hands, str(path))
    return write_result_npz(path, hands, tuple(f"{side}_valid" for side in SIDES))


def read_hands(path) -> dict[str, np.ndarray]:
    """The arrays of a ``hands.npz``, or `InputError` naming the problem."""
    hands = read_result_npz(path, "hands")
    _check(hands, str(path))
    return hands


@jax.jit
def _hand_forward(hand, global_orient, hand_pose):
    betas = jnp.zeros(hand.shapedirs_cm.shape[0], global_orient.dtype)
    return jax.vmap(smplx_jax.hand_forward, in_axes=(None, 0, 0, None))(hand, rotvec_to_rotmat(global_orient),
                                                                         hand_pose, betas)


def hand_meshes(hand: smplx_jax.HandModel, global_orient, hand_pose) -> smplx_jax.HandOutput:
    """The hand model's vertices ``(T, N, 3)`` and 21 joints ``(T, 21, 3)`` (wrist at the origin) of ``T`` frames
    of one side of a hands.npz (the mean shape), computed in padded batches (one compilation per batch size)."""
    arrays = (np.asarray(global_orient, np.float32), np.asarray(hand_pose, np.float32))
    if not len(arrays[0]):
        count = hand.vertex_ids.shape[0]
        return smplx_jax.HandOutput(np.zeros((0, count, 3), np.float32), np.zeros((0, 21, 3), np.float32))
    return map_in_buckets(lambda batch, _: _hand_forward(hand, *batch), arrays, BUCKETS)
