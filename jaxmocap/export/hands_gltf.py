"""glTF 2.0 export of a ``hands.npz``: each hand with a valid frame as the mesh of the hand model H (the body
model's mean shape) skinned to its 16 joints, named as in SMPL-X (``left_wrist``, ``left_index1``, ...), in the
y-up world frame of `jaxmocap.export.animation`. Each wrist sits at the depth and in front of the pixel its
weak-perspective camera gives, so the hands keep their places in the image relative to each other.
"""

from pathlib import Path

import numpy as np

import smplx_jax
from jaxmocap.errors import InputError
from jaxmocap.export.animation import CAMERA_TO_WORLD, Animation, end_sites, held_frames, weak_perspective_origin
from jaxmocap.export.gltf import SkinnedMesh, write_meshes
from smplx_jax import SIDES, constants
from smplx_jax.rotations import rotvec_to_rotmat

HAND_JOINTS = {"left": (constants.LEFT_WRIST,) + constants.LEFT_HAND_JOINTS,
               "right": (constants.RIGHT_WRIST,) + constants.RIGHT_HAND_JOINTS}  # body joint ids of H's 16


def hand_mesh(model: smplx_jax.BodyModel, hands: dict, side: str, focal_px: float | None = None) -> SkinnedMesh:
    """One side of a hands file as a skinned, animated mesh; invalid frames hold the previous valid frame's pose."""
    hand = smplx_jax.hand_model(model, side)
    held = held_frames(np.asarray(hands[f"{side}_valid"], bool))
    rotvecs = np.concatenate([np.asarray(hands[f"{side}_global_orient"])[held][:, None],
                              np.asarray(hands[f"{side}_hand_pose"])[held]], axis=1)
    local = np.asarray(rotvec_to_rotmat(rotvecs), np.float64)
    local[:, 0] = CAMERA_TO_WORLD @ local[:, 0]
    wrist = weak_perspective_origin(np.asarray(hands[f"{side}_camera_scale"])[held],
                                    np.asarray(hands[f"{side}_camera_trans"])[held], hands["image_size"], focal_px)
    ids = list(HAND_JOINTS[side])
    betas = np.zeros(model.num_betas)
    rest_joints = np.asarray(model.joint_template, np.float64)
    anim = Animation(
        names=tuple(constants.JOINT_NAMES[j] for j in ids), parents=hand.parents, rest_joints=rest_joints[ids],
        local_rotmats=local, root_positions=wrist @ CAMERA_TO_WORLD.T, betas=betas, fps=float(hands["fps"]),
        end_sites=end_sites(model, betas, rest_joints)[ids])
    return SkinnedMesh(f"{side}_hand", np.asarray(hand.template_cm, np.float64).T, np.asarray(hand.faces),
                       np.asarray(hand.weights_t, np.float64).T, anim)


def write_hands_gltf(path, model: smplx_jax.BodyModel, hands: dict, focal_px: float | None = None) -> Path:
    """Write the hands with a valid frame as glTF (`jaxmocap.export.gltf.write_meshes`); `InputError` if none has."""
    sides = [side for side in SIDES if np.asarray(hands[f"{side}_valid"]).any()]
    if not sides:
        raise InputError("neither hand has a valid frame to export")
    return write_meshes(path, [hand_mesh(model, hands, side, focal_px) for side in sides])
