"""Raw network outputs -> SMPL-X parameters (`smplx_jax.SMPLXParams`) and image-space joints."""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

import smplx_jax
from jaxmocap.regressors.body import BodyOutput
from jaxmocap.regressors.crops import Window, body_to_image, hand_to_image
from jaxmocap.regressors.hand import BETAS, CAMERA, POSE
from smplx_jax.rotations import rotmat_to_rotvec, rotvec_to_rotmat

_INDEX1 = 5  # OpenPose hand joint 5 = SMPL-X joint 40/25 (index1): FrankMocap's hand origin
_NEGATED = np.zeros(61, bool)  # camera tx and the y, z of the 16 axis-angles
_NEGATED[1] = True
_NEGATED[POSE] = np.tile([False, True, True], 16)


def mirror_hand_params(raw: Float[ArrayLike, "N 61"]) -> Float[Array, "N 61"]:
    """Left <-> right for a left-right flipped crop: negate camera tx and the y, z of every axis-angle (wrist
    included). Its own inverse."""
    return jnp.where(_NEGATED, -raw, raw)


class HandPrediction(NamedTuple):
    """A hand regressor's prediction for N hands, decoded into the image and the hand's own side."""

    wrist_glob_rotvec: Float[Array, "N 3"]  # global wrist orientation (camera frame), for copy-and-paste
    hand_pose: Float[Array, "N 15 3"]  # absolute (mean hand added), of the hand's own side
    betas: Float[Array, "N 10"]
    camera: Float[Array, "N 3"]  # [s, tx, ty] of the un-flipped crop
    joints_2d: Float[Array, "N 21 2"]  # OpenPose hand order, image pixels


class BodyPrediction(NamedTuple):
    """The body regressor's prediction for N bodies as SMPL-X parameters, with their cameras and joints."""

    params: smplx_jax.SMPLXParams  # batched over N; hands at the model's mean hand until copy-and-paste
    camera: Float[Array, "N 3"]
    joints_2d: Float[Array, "N 127 2"]  # smplx joint order, image pixels


@jax.jit
def decode_hands(model: smplx_jax.BodyModel, right_hand: smplx_jax.HandModel, raw: Float[Array, "N 61"],
                 is_left: Bool[Array, "N"], window: Window) -> HandPrediction:
    """``raw`` as the network predicts it for right-hand (left ones flipped) crops cut with ``window``."""
    is_left = jnp.asarray(is_left, bool)
    n = raw.shape[0]
    joints = jax.vmap(_right_hand_joints, in_axes=(None, None, 0))(model, right_hand, raw)
    joints = joints.at[..., 0].multiply(jnp.where(is_left, -1.0, 1.0)[:, None])
    raw = jnp.where(is_left[:, None], mirror_hand_params(raw), raw)
    pose = raw[:, POSE].reshape(n, 16, 3)
    relative = pose[:, 1:]
    absolute = jnp.where(is_left[:, None, None], smplx_jax.hand_pose_from_relative(model, relative, "left"),
                         smplx_jax.hand_pose_from_relative(model, relative, "right"))
    return HandPrediction(pose[:, 0], absolute, raw[:, BETAS], raw[:, CAMERA],
                          hand_to_image(joints, raw[:, CAMERA], window))


def _right_hand_joints(model, right_hand, raw):
    pose = raw[POSE].reshape(16, 3)
    fingers = smplx_jax.hand_pose_from_relative(model, pose[1:], "right")
    joints = smplx_jax.hand_forward(right_hand, rotvec_to_rotmat(pose[0]), fingers, raw[BETAS]).joints
    return joints - joints[_INDEX1]


@jax.jit
def decode_bodies(model: smplx_jax.BodyModel, out: BodyOutput, window: Window) -> BodyPrediction:
    """SMPL rotations -> SMPL-X (global orientation and body joints 1..21; SMPL's hands 22, 23 dropped)."""
    params = jax.vmap(body_params, in_axes=(None, 0, 0))(model, out.rotmats, out.betas)
    joints = jax.vmap(smplx_jax.forward_joints, in_axes=(None, 0))(model, params)
    return BodyPrediction(params, out.camera, body_to_image(joints, out.camera, window))


def body_params(model: smplx_jax.BodyModel, rotmats: Float[Array, "24 3 3"], betas: Float[Array, "10"]
                ) -> smplx_jax.SMPLXParams:
    """One body's SMPL rotations -> SMPL-X parameters: global orientation and body joints 1..21 (SMPL's hands 22,
    23 dropped), the model's mean hands, zero face and translation."""
    rotvecs = rotmat_to_rotvec(rotmats)
    def zeros(n):
        return jnp.zeros(n, rotvecs.dtype)
    return smplx_jax.SMPLXParams(
        global_orient=rotvecs[0], body_pose=rotvecs[1:22], left_hand_pose=model.hand_mean[0].reshape(15, 3),
        right_hand_pose=model.hand_mean[1].reshape(15, 3), jaw_pose=zeros(3), leye_pose=zeros(3),
        reye_pose=zeros(3), betas=betas, expression=zeros(model.num_expression), transl=zeros(3))
