"""Optimization integration: fit SMPL-X (pose, both hands, shape, weak-perspective camera) to 2D keypoints.

    result = fit(model, keypoints)                 # keypoints (T, 67, 3): BODY_25, left hand, right hand; x, y, conf
    result = fit(model, keypoints, init=params)    # from a regressor / IK / copy-paste result (batched SMPLXParams)

Each frame is an independent robust least-squares problem (`solver.solve`, Levenberg-Marquardt with an analytic
matrix-free Jacobian), vmapped over frames and jitted once per padded batch size (`BUCKETS`; larger inputs run
in chunks of the largest). Residuals: confidence-weighted Cauchy-robust reprojection of the 67 keypoints, a prior
that keeps each joint near the initial pose (weaker for hands), shape L2 and elbow/knee bending limits.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from jaxmocap.integrate import solver
from jaxmocap.sharding import shard_frames
from jaxmocap.integrate.camera import weak_perspective_from_points
from smplx_jax import BodyModel, SMPLXParams, constants

BUCKETS = (1, 8, 32, 64)  # padded batch sizes; longer inputs run in chunks of 64 (faster here than 1024: cache)
MIN_KEYPOINTS = 3  # fewer visible keypoints: the frame has no person to fit

OK, NO_KEYPOINTS, FAILED = 0, 1, 2  # FitResult.status

FitConfig = solver.SolverConfig


class FitResult(NamedTuple):
    """Per-frame fit (leading axis T). ``status``: 0 fitted, 1 too few keypoints, 2 numerical failure; frames
    with a non-zero status hold the initial parameters and camera."""

    params: SMPLXParams
    camera_scale: Float[Array, "T"]
    camera_trans: Float[Array, "T 2"]
    status: Int[Array, "T"]
    reprojection_error_px: Float[Array, "T"]  # mean pixel distance over keypoints with confidence > 0 (0 if none)
    initial_reprojection_error_px: Float[Array, "T"]
    accepted_steps: Int[Array, "T"]

    @property
    def valid(self):
        return self.status == OK


_KEYPOINT_MODELS: dict[int, tuple[BodyModel, solver.KeypointModel]] = {}


def openpose_keypoint_model(model: BodyModel) -> solver.KeypointModel:
    """The fit's constants for the 67 OpenPose keypoints (cached per model object)."""
    hit = _KEYPOINT_MODELS.get(id(model))
    if hit is None or hit[0] is not model:
        hit = (model, solver.keypoint_model(model, constants.OPENPOSE67_FROM_SMPLX))
        _KEYPOINT_MODELS[id(model)] = hit
    return hit[1]


def default_pose(dtype=jnp.float32) -> Float[Array, "55 3"]:
    """The fit's default start: facing the camera upright in image axes (y down: pi about x), arms lowered,
    elbows slightly bent, flat hands."""
    theta = np.zeros((55, 3), np.float32)
    theta[0] = (np.pi, 0, 0)
    theta[16], theta[17] = (0, 0, -1.1), (0, 0, 1.1)  # shoulders
    theta[18], theta[19] = (0, -0.3, 0), (0, 0.3, 0)  # elbows
    return jnp.asarray(theta, dtype)


def _prior_weights(config: FitConfig) -> np.ndarray:
    prior = np.zeros(55, np.float32)
    prior[0] = config.prior_global
    prior[1:22] = config.prior_body
    prior[25:55] = config.prior_hand
    return prior


FREE_JOINTS = tuple(j not in (22, 23, 24) for j in range(55))  # jaw and eyes are not seen by 67 keypoints


def _fit_one(km, keypoints, theta, betas, cam, has_cam, config: FitConfig):
    finite = jnp.all(jnp.isfinite(keypoints), axis=-1)
    conf = jnp.where(finite & (keypoints[:, 2] > 0), keypoints[:, 2], 0.0)
    target = jnp.where(finite[:, None], keypoints[:, :2], 0.0)
    seen = conf > 0
    x0 = solver.model_keypoints(km, theta, betas)
    s_guess, t_guess = weak_perspective_from_points(x0[:, :2], target, conf)
    cam = jnp.where(has_cam, cam, jnp.concatenate([s_guess[None], t_guess]))
    sref = jnp.where(jnp.isfinite(cam[0]) & (cam[0] > 0), cam[0], 1.0)
    problem = solver.Problem(target, conf, theta, jnp.asarray(_prior_weights(config)), sref)
    out = solver.solve(km, problem, theta, betas, cam, FREE_JOINTS, True, True, config)

    def reproj(theta, betas, cam):
        x = solver.model_keypoints(km, theta, betas)
        err = jnp.linalg.norm(cam[0] * x[:, :2] + cam[1:] - target, axis=-1)
        return jnp.sum(jnp.where(seen, err, 0.0)) / jnp.maximum(jnp.sum(seen), 1)

    err0 = reproj(theta, betas, cam)
    err = reproj(out.theta, out.betas, out.cam)
    enough = jnp.sum(seen) >= MIN_KEYPOINTS
    finite_out = (jnp.all(jnp.isfinite(out.theta)) & jnp.all(jnp.isfinite(out.betas)) & jnp.all(jnp.isfinite(out.cam))
                  & jnp.isfinite(err))
    status = jnp.where(~enough, NO_KEYPOINTS, jnp.where(finite_out, OK, FAILED)).astype(jnp.int32)
    keep = status == OK
    pick = lambda a, b: jnp.where(keep, a, b)  # noqa: E731
    err0 = jnp.where(enough & jnp.isfinite(err0), err0, 0.0)
    return (pick(out.theta, theta), pick(out.betas, betas), pick(out.cam, cam), status, pick(err, err0), err0,
            jnp.where(keep, out.accepted, 0))


@functools.partial(jax.jit, static_argnames=("config",))
def _fit_batch(km, keypoints, theta, betas, cam, has_cam, config: FitConfig):
    return jax.vmap(functools.partial(_fit_one, config=config), in_axes=(None, 0, 0, 0, 0, 0))(
        km, keypoints, theta, betas, cam, has_cam)


def bucket_size(n: int) -> int:
    return next((b for b in BUCKETS if b >= n), BUCKETS[-1])


def full_pose_of(params: SMPLXParams) -> Float[Array, "T 55 3"]:
    return jax.vmap(SMPLXParams.full_pose)(params)


def params_from_full_pose(theta, betas, num_expression: int) -> SMPLXParams:
    return jax.vmap(lambda t, b: solver.params_of(t, b, num_expression))(theta, betas)


def _check(name, value, shape, dtype):
    value = np.asarray(value, dtype)
    if value.shape != shape:
        raise ValueError(f"{name} must have shape {shape}, got {value.shape}")
    if not np.all(np.isfinite(value)):
        frames = np.flatnonzero(~np.isfinite(value).reshape(shape[0], -1).all(1))
        more = "..." if len(frames) > 5 else ""
        raise ValueError(f"{name} holds NaN or inf values (frames {frames[:5].tolist()}{more})")
    return value


def fit(model: BodyModel, keypoints, init: SMPLXParams | None = None, camera_scale=None, camera_trans=None, *,
        iterations: int = 20, config: FitConfig | None = None, progress=None) -> FitResult:
    """Fit every frame of ``keypoints (T, 67, 3)`` (pixels; confidence 0 = missing; NaN/inf keypoints are treated
    as missing). ``init``: batched `SMPLXParams` (T leading; hand poses absolute; ``transl`` ignored, fits use 0);
    default `default_pose` with mean shape. Camera: given, or fitted to the initial pose's keypoints.
    ``progress(n)`` is called after each chunk with the number of frames done. Runs in the model's precision
    (float32; a model loaded as float64 under ``jax.enable_x64`` fits in float64)."""
    config = dataclasses.replace(config or FitConfig(), iterations=iterations)
    dtype = np.dtype(model.joint_template.dtype)
    keypoints = np.asarray(keypoints, dtype)
    if keypoints.ndim != 3 or keypoints.shape[1:] != (67, 3):
        raise ValueError(f"keypoints must have shape (T, 67, 3), got {keypoints.shape}")
    t = keypoints.shape[0]
    nb = model.num_betas
    if init is None:
        theta = np.broadcast_to(np.asarray(default_pose(dtype)), (t, 55, 3))
        betas = np.zeros((t, nb), dtype)
    else:
        theta = _check("init pose", full_pose_of(init), (t, 55, 3), dtype)
        betas = _check("init betas", init.betas, (t, nb), dtype)
    has_cam = camera_scale is not None
    if has_cam:
        cam = np.concatenate([_check("camera_scale", camera_scale, (t,), dtype)[:, None],
                              _check("camera_trans", camera_trans, (t, 2), dtype)], axis=1)
    else:
        cam = np.ones((t, 3), dtype)
    km = openpose_keypoint_model(model)
    outs = []
    for start in range(0, t, BUCKETS[-1]):
        stop = min(t, start + BUCKETS[-1])
        n = stop - start
        size = bucket_size(n)
        pad = lambda a: np.concatenate([a[start:stop], np.repeat(a[start:start + 1], size - n, 0)])  # noqa: E731
        kp = pad(keypoints)
        kp[n:] = 0.0  # padding frames have no keypoints
        frames = shard_frames((kp, pad(theta), pad(betas), pad(cam), np.full((size,), has_cam)), size)
        out = _fit_batch(km, *frames, config)
        outs.append([np.asarray(o)[:n] for o in out])
        if progress is not None:
            progress(n)
    theta, betas, cam, status, err, err0, acc = (np.concatenate(parts) for parts in zip(*outs))
    params = params_from_full_pose(jnp.asarray(theta), jnp.asarray(betas), model.num_expression)
    return FitResult(params, jnp.asarray(cam[:, 0]), jnp.asarray(cam[:, 1:]), jnp.asarray(status), jnp.asarray(err),
                     jnp.asarray(err0), jnp.asarray(acc))


__all__ = ["BUCKETS", "FitConfig", "FitResult", "default_pose", "fit", "openpose_keypoint_model"]
