"""Training losses of the two regressors for ONE example; the trainer vmaps them over a batch and averages.

    terms = jax.vmap(hand_losses, in_axes=(None, None, 0, 0))(model, right_hand, raw, examples)
    loss = terms["total"].mean()

A term against labels is the mean over coordinates (or parameters) of squared differences, a joint masked off
counting as zero in it (SPIN's reduction, and that of FrankMocap's author's later hand code); a term whose label is
masked off is exactly 0, with finite gradients. Regularisers are sums of squares.
"""

from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

import smplx_jax
from jaxmocap.regressors.body import BodyOutput
from jaxmocap.regressors.hand import BETAS, CAMERA, NUM_PARAMS, POSE
from smplx_jax.constants import BODY25_FROM_SMPLX
from smplx_jax.rotations import rotmat_to_rotvec, rotvec_to_rotmat
from train.datasets.sample import BodyExample, HandExample

HAND_ORIGIN = 5  # OpenPose hand joint 5 (index1): origin of the hand network's weak-perspective camera
MIDDLE_MCP, MIDDLE_PIP = 9, 10  # OpenPose hand joints of the middle finger's first knuckle (proximal phalanx)
MID_HIP = 8  # BODY_25 joint the body's 3D joints are aligned at (SMPL-X pelvis)
_BODY25 = jnp.array(BODY25_FROM_SMPLX)


class HandLossWeights(NamedTuple):
    """FrankMocap's lambdas (paper section 3.2)."""

    pose: float = 10.0
    joints_3d: float = 100.0
    joints_2d: float = 10.0
    shape: float = 0.1


class BodyLossWeights(NamedTuple):
    """SPIN's defaults (``train_options.py``: keypoint_loss_weight 5 for 2D and 3D, pose_loss_weight 1,
    beta_loss_weight 0.001, the camera term exp(-10 s)^2 with weight 1, the sum times 60). SPIN's shape_loss_weight
    is 0 (its per-vertex term); our stand-in, the regulariser ||betas||^2, is likewise off by default: turn it on
    for data without betas labels."""

    pose: float = 1.0
    betas: float = 0.001
    joints_3d: float = 5.0
    joints_2d: float = 5.0
    camera: float = 1.0
    shape: float = 0.0
    overall: float = 60.0


def right_hand_joints(model: smplx_jax.BodyModel, right_hand: smplx_jax.HandModel,
                      raw: Float[Array, "61"]) -> Float[Array, "21 3"]:
    """The 21 OpenPose-order joints (metres, camera frame, wrist at the origin) of one raw hand prediction."""
    pose = raw[POSE].reshape(16, 3)
    fingers = smplx_jax.hand_pose_from_relative(model, pose[1:], "right")
    return smplx_jax.hand_forward(right_hand, rotvec_to_rotmat(pose[0]), fingers, raw[BETAS]).joints


def hand_crop_joints(joints: Float[Array, "21 3"], camera: Float[Array, "3"]) -> Float[Array, "21 2"]:
    """The hand network's weak perspective into crop coordinates [-1, 1]: ``(X - X[index1] + t) s``."""
    return (joints[:, :2] - joints[HAND_ORIGIN, :2] + camera[1:]) * camera[0]


def hand_losses(model: smplx_jax.BodyModel, right_hand: smplx_jax.HandModel, raw: Float[Array, "61"],
                example: HandExample, weights: HandLossWeights = HandLossWeights()) -> dict[str, Float[Array, ""]]:
    """FrankMocap's hand losses (Eq. 7-9) of one raw prediction (camera 3, wrist + 15 mean-relative finger
    axis-angles 48, betas 10) against one right-hand example: ``pose`` (L_theta), ``joints_3d`` (L_3D),
    ``joints_2d`` (L_2D), ``shape`` (L_reg) and their weighted ``total``.

    L_3D compares wrist-aligned joints after scaling the label so that its middle finger's first knuckle (MCP to
    PIP, OpenPose joints 9-10) is as long as the mean-shape SMPL-X hand's, as FrankMocap's author normalises hand
    datasets of different scales to SMPL-X's; a fixed reference keeps the target independent of the prediction
    (no gradient through the scale) and agrees with L_reg, which pulls betas to the mean shape.
    """
    if raw.shape != (NUM_PARAMS,):
        raise ValueError(f"raw: expected ({NUM_PARAMS},) for one example (vmap over a batch), got {raw.shape}")
    if example.joints_2d.shape != (21, 2):
        raise ValueError(f"example: expected one HandExample (joints_2d (21, 2)), got joints_2d "
                         f"{example.joints_2d.shape}")
    pose_label = jnp.concatenate([example.pose[:1], smplx_jax.hand_pose_to_relative(model, example.pose[1:], "right")])
    pose = jnp.where(example.pose_mask, jnp.mean((raw[POSE] - pose_label.reshape(48)) ** 2), 0.0)

    joints = right_hand_joints(model, right_hand, raw)
    label = example.joints_3d - example.joints_3d[0]
    knuckle = right_hand.joint_template[5] - right_hand.joint_template[4]  # middle2 - middle1 (SMPL-X order)
    label = label * jnp.linalg.norm(knuckle) / _safe_norm(label[MIDDLE_PIP] - label[MIDDLE_MCP])
    joints_3d = jnp.where(example.joints_3d_mask, jnp.mean((joints - label) ** 2), 0.0)

    crop = hand_crop_joints(joints, raw[CAMERA])
    joints_2d = _masked_mean_square(crop - example.joints_2d, example.joints_2d_mask)
    shape = jnp.sum(raw[BETAS] ** 2)
    terms = dict(pose=pose, joints_3d=joints_3d, joints_2d=joints_2d, shape=shape)
    return terms | dict(total=sum(getattr(weights, name) * value for name, value in terms.items()))


def body_joints(model: smplx_jax.BodyModel, output: BodyOutput) -> Float[Array, "25 3"]:
    """BODY_25 joints (metres, camera frame, no translation) of one body prediction, hands at the mean hand."""
    rotvecs = rotmat_to_rotvec(output.rotmats[:22])
    mean_hands = model.hand_mean.reshape(2, 15, 3)
    params = smplx_jax.SMPLXParams.zeros(model.num_betas, model.num_expression, output.betas.dtype).replace(
        global_orient=rotvecs[0], body_pose=rotvecs[1:], left_hand_pose=mean_hands[0],
        right_hand_pose=mean_hands[1], betas=output.betas)
    return smplx_jax.forward_joints(model, params)[_BODY25]


def body_losses(model: smplx_jax.BodyModel, output: BodyOutput, example: BodyExample,
                weights: BodyLossWeights = BodyLossWeights()) -> dict[str, Float[Array, ""]]:
    """SPIN's losses on SMPL-X for one body prediction (`BodyOutput` of one example: SMPL rotations, of which
    0..21 are used, betas, camera): ``pose`` (rotation-matrix MSE), ``betas`` (MSE), ``joints_3d`` (BODY_25
    aligned at the mid-hip), ``joints_2d`` (crop coordinates ``X s + t``), ``camera`` (exp(-10 s)^2, keeps the
    scale positive), ``shape`` (||betas||^2) and the weighted ``total``."""
    if output.rotmats.shape != (24, 3, 3) or output.betas.shape != (model.num_betas,) or output.camera.shape != (3,):
        raise ValueError(f"output: expected one BodyOutput (rotmats (24, 3, 3), betas ({model.num_betas},), camera "
                         f"(3,)), got {output.rotmats.shape}, {output.betas.shape}, {output.camera.shape}")
    if example.joints_2d.shape != (25, 2):
        raise ValueError(f"example: expected one BodyExample (joints_2d (25, 2)), got {example.joints_2d.shape}")
    pose = jnp.where(example.pose_mask, jnp.mean((output.rotmats[:22] - rotvec_to_rotmat(example.pose)) ** 2), 0.0)
    betas = jnp.where(example.betas_mask, jnp.mean((output.betas - example.betas) ** 2), 0.0)

    joints = body_joints(model, output)
    aligned, label = joints - joints[MID_HIP], example.joints_3d - example.joints_3d[MID_HIP]
    joints_3d = jnp.where(example.joints_3d_mask, jnp.mean((aligned - label) ** 2), 0.0)

    scale, shift = output.camera[0], output.camera[1:]
    joints_2d = _masked_mean_square(joints[:, :2] * scale + shift - example.joints_2d, example.joints_2d_mask)
    camera = jnp.exp(-10.0 * scale) ** 2
    shape = jnp.sum(output.betas ** 2)
    terms = dict(pose=pose, betas=betas, joints_3d=joints_3d, joints_2d=joints_2d, camera=camera, shape=shape)
    total = weights.overall * sum(getattr(weights, name) * value for name, value in terms.items())
    return terms | dict(total=total)


def _masked_mean_square(diff: Float[Array, "J 2"], mask) -> Float[Array, ""]:
    """Mean over all coordinates of the squared differences, rows masked off counting as zero."""
    return jnp.mean(jnp.where(mask[:, None], diff ** 2, 0.0))


def _safe_norm(v: Float[ArrayLike, "3"]) -> Float[Array, ""]:
    """|v|, and 1 for a zero vector (a masked-off label), with finite gradients either way."""
    sq = jnp.sum(v * v)
    return jnp.sqrt(jnp.where(sq > 0, sq, 1.0))

