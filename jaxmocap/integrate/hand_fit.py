"""A hand on its own (no body): the hand model H fitted to one hand's landmarks (``jaxmocap run --mode hands``).

    result = fit_hands(model, "left", world, world_conf, keypoints)   # (T, 21, 3) each; `HandFit` of T frames

Per frame, as the whole-body path does for a body: the wrist's rotation is first aligned in closed form to the
palm of the 21 world landmarks (`palm_rotation`), then IK to those landmarks (`inverse_kinematics.ik_one`: wrist and
15 finger joints, up to a scale and an offset), then the same optimistix least-squares fit to the 21 2D keypoints
(`fitting.fit_one`) through a weak-perspective camera of its own. The body stays in its rest pose with its mean
shape, so the wrist's rotation is the hand's global orientation and its joints are those of the hand model H
(`smplx_jax.hand_forward`) moved by the rest wrist's position, which the camera absorbs: a joint ``X`` of H (wrist at
the origin) lands at pixel ``camera_scale * X[:2] + camera_trans``. Pure and jit-/vmap-able (`hand_fit_one`).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from jaxmocap.buckets import map_in_buckets
from jaxmocap.compile_cache import disk_jit
from jaxmocap.integrate.fitting import OK, FitConfig, fit_one
from jaxmocap.integrate.inverse_kinematics import LEFT_HAND_IK_JOINTS, RIGHT_HAND_IK_JOINTS, IKConfig, ik_one
from jaxmocap.integrate.keypoints import KeypointModel, keypoint_model, keypoints_cm
from smplx_jax import BodyModel, constants
from smplx_jax.rotations import rotmat_to_rotvec

WRIST = {"left": constants.LEFT_WRIST, "right": constants.RIGHT_WRIST}
HAND21 = {"left": constants.LEFT_HAND21_FROM_SMPLX, "right": constants.RIGHT_HAND21_FROM_SMPLX}
FREE = {"left": LEFT_HAND_IK_JOINTS, "right": RIGHT_HAND_IK_JOINTS}
BUCKETS = (64,)  # one padded batch size: tracing the two solves takes ~12 s, so one compiled fit serves all
PALM = (0, 5, 9, 13, 17)  # wrist and the four knuckles (OpenPose hand order): the palm, nearly rigid

HAND_IK = IKConfig()  # the whole-body path's hand IK settings
# The 2D fit from the IK start: the wrist (a body joint's prior) and the fingers' hinges stay near what the 3D
# landmarks say; errors are robust beyond 2 cm (a hand is ~18 cm long).
HAND_FIT = FitConfig(prior_body=0.02, prior_finger_hinge=0.05, prior_finger_range=0.2, robust_scale=0.02,
                     linear_solver="cg")


class HandFit(NamedTuple):
    """One hand's fit: one frame from `hand_fit_one`, a leading axis T from `fit_hands`. Frames not ``valid``
    (too few keypoints, or a numerical failure) hold the IK start."""

    global_orient: Float[Array, "*T 3"]
    hand_pose: Float[Array, "*T 15 3"]
    camera_scale: Float[Array, "*T"]
    camera_trans: Float[Array, "*T 2"]
    valid: Bool[Array, "*T"]
    reprojection_error_px: Float[Array, "*T"]


def hand_keypoint_model(model: BodyModel, side: str) -> KeypointModel:
    """The fit's constants for the 21 keypoints of one hand."""
    return keypoint_model(model, HAND21[side])


def palm_rotation(model_palm: Float[Array, "5 3"], target_palm: Float[Array, "5 3"]) -> Float[Array, "3 3"]:
    """The rotation best taking the model's palm points onto the target's, each about its centroid (Kabsch)."""
    a = model_palm - model_palm.mean(0)
    b = target_palm - target_palm.mean(0)
    u, _, vt = jnp.linalg.svd(b.T @ a)
    d = jnp.sign(jnp.linalg.det(u @ vt))
    return u @ jnp.diag(jnp.array([1.0, 1.0, 1.0], a.dtype).at[2].set(d)) @ vt


class SideIndices(NamedTuple):
    """One side's indices as arrays (traced: both sides share one compiled fit)."""

    wrist: Int[Array, ""]
    fingers: Int[Array, "15"]
    free: Float[Array, "55"]


def side_indices(side, dtype) -> SideIndices:
    """`SideIndices` of ``side``: ``"left"``, ``"right"``, or a boolean array, true for the left hand."""
    left = jnp.asarray(side == "left") if isinstance(side, str) else side
    return SideIndices(jnp.where(left, WRIST["left"], WRIST["right"]),
                 jnp.where(left, jnp.arange(25, 40), jnp.arange(40, 55)),
                 jnp.where(left, jnp.asarray(FREE["left"], dtype), jnp.asarray(FREE["right"], dtype)))


def palm_start(km: KeypointModel, side, world: Float[Array, "21 3"]) -> Float[Array, "55 3"]:
    """The body at rest with the ``side`` hand's wrist turned so that its palm best matches that of ``world``
    (Kabsch on the wrist and the four knuckles; missing points count as zeros)."""
    dtype = km.body.joint_template.dtype
    rest = jnp.zeros((55, 3), dtype)
    world = jnp.where(jnp.all(jnp.isfinite(world), -1, keepdims=True), world, 0.0)
    model_palm = keypoints_cm(km, rest, jnp.zeros(km.body.num_betas, dtype)).T[jnp.array(PALM)]
    turn = palm_rotation(model_palm, world[jnp.array(PALM)])
    return rest.at[side_indices(side, dtype).wrist].set(rotmat_to_rotvec(turn))


def hand_ik_one(km: KeypointModel, side, world, world_conf, ik_config=HAND_IK, start=None) -> Float[Array, "55 3"]:
    """The pose (55, 3; the body at rest) whose ``side`` hand (``"left"``, ``"right"``, or a boolean array, true
    for left) best matches ``world (21, 3)``, metric landmarks in image-aligned axes (x right, y down) with
    confidence ``world_conf (21,)``, up to a scale and an offset: IK of wrist and fingers from ``start`` (default
    `palm_start`); ``km`` is that side's `hand_keypoint_model`."""
    dtype = km.body.joint_template.dtype
    start = palm_start(km, side, world) if start is None else start
    finite = jnp.all(jnp.isfinite(world), -1)
    world = jnp.where(finite[:, None], world, 0.0)
    pose, _, _, _ = ik_one(km, world, jnp.where(finite, world_conf, 0.0), start, jnp.zeros(km.body.num_betas, dtype),
                           side_indices(side, dtype).free, jnp.zeros((), dtype), ik_config)
    return pose


def hand_fit_from(km: KeypointModel, side, keypoints, pose, fit_config=HAND_FIT) -> HandFit:
    """The fit of the ``side`` hand (as in `hand_ik_one`) of ``pose (55, 3)`` (the body at rest) to ``keypoints
    (21, 3)``: pixels x, y and a confidence (0 or non-finite: missing), through a weak-perspective camera fitted
    to the start."""
    dtype = km.body.joint_template.dtype
    ids = side_indices(side, dtype)
    betas = jnp.zeros(km.body.num_betas, dtype)
    lens = (jnp.zeros((), dtype), jnp.zeros(2, dtype))
    fitted = fit_one(km, keypoints, pose, betas, None, lens, fit_config, free=ids.free,
                     fit_betas=jnp.zeros((), dtype))
    out = fitted.params.full_pose()
    rest_wrist = km.body.joint_template[ids.wrist, :2]
    return HandFit(out[ids.wrist], out[ids.fingers], fitted.camera_scale,
                   fitted.camera_trans + fitted.camera_scale * rest_wrist, fitted.status == OK,
                   fitted.reprojection_error_px)


def hand_fit_one(km: KeypointModel, side, world, world_conf, keypoints, ik_config=HAND_IK,
                 fit_config=HAND_FIT) -> HandFit:
    """One frame of one ``side``: `hand_ik_one` to the world landmarks, then `hand_fit_from` to the 2D keypoints."""
    return hand_fit_from(km, side, keypoints, hand_ik_one(km, side, world, world_conf, ik_config), fit_config)


def start_pose(side, global_orient, hand_pose):
    """The body at rest with the ``side`` hand's (as in `hand_ik_one`) wrist rotated by ``global_orient (3,)``
    and its fingers at ``hand_pose (15, 3)`` (a start for `hand_fit_from`, e.g. a regressor's)."""
    hand_pose = jnp.asarray(hand_pose)
    ids = side_indices(side, hand_pose.dtype)
    return jnp.zeros((55, 3), hand_pose.dtype).at[ids.wrist].set(global_orient).at[ids.fingers].set(hand_pose)


@disk_jit(static_argnames="fit_config")
def _fit_batch(km, left, world, world_conf, keypoints, start, fit_config):
    def one(w, c, k, p):
        pose = hand_ik_one(km, left, w, c) if start is None else start_pose(left, *p)
        return hand_fit_from(km, left, k, pose, fit_config)
    return jax.vmap(one)(world, world_conf, keypoints, start)


def fit_hands(model: BodyModel, side: str, world, world_conf, keypoints, *, start=None,
              km: KeypointModel | None = None, iterations: int = 20) -> HandFit:
    """`hand_fit_one` of every frame of one side: ``world (T, 21, 3)``, ``world_conf (T, 21)``, ``keypoints
    (T, 21, 3)``; or with ``start = (global_orient (T, 3), hand_pose (T, 15, 3))`` (a regressor's), the fit from
    there (``world`` unused). Vmapped in padded batches (`BUCKETS`); ``km``: the side's
    `hand_keypoint_model` if made already. Runs in float32."""
    if side not in WRIST:
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    t = len(np.asarray(keypoints))
    arrays = [np.asarray(a, np.float32) for a in (world, world_conf, keypoints)]
    for name, a, shape in zip(("world", "world_conf", "keypoints"), arrays, ((21, 3), (21,), (21, 3))):
        if a.shape != (t,) + shape:
            raise ValueError(f"{name} must have shape {(t,) + shape}, got {a.shape}")
    if start is not None:
        start = tuple(np.asarray(a, np.float32) for a in start)
        if start[0].shape != (t, 3) or start[1].shape != (t, 15, 3):
            raise ValueError(f"start must be ((T, 3), (T, 15, 3)) with T = {t}, got {[a.shape for a in start]}")
    if not t:
        return HandFit(*(np.zeros((0,) + s, np.float32) for s in ((3,), (15, 3), (), (2,))), np.zeros(0, bool),
                       np.zeros(0, np.float32))
    km = hand_keypoint_model(model, side) if km is None else km
    fit_config = dataclasses.replace(HAND_FIT, iterations=iterations)

    def chunk(frames, n):
        w, c, k, p = frames
        k = np.concatenate([k[:n], np.zeros_like(k[n:])])  # padding frames have no keypoints
        return jax.block_until_ready(_fit_batch(km, jnp.asarray(side == "left"), w, c, k, p, fit_config))

    return jax.tree.map(np.asarray, map_in_buckets(chunk, (*arrays, start), BUCKETS))
