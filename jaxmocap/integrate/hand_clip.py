"""One hand's frames as one least-squares problem (``jaxmocap run --mode hands``): every frame's wrist rotation,
fingers and camera, solved together with the motion between frames.

    result = fit_hand_clip(model, "left", keypoints, start, focal_length=f, principal_point=c, fps=60.0,
                           keypoint_sigma_px=sigma, directions=bone_directions, direction_weight=their_confidence)

The hand is `hand_fit`'s (the body at rest, the wrist's rotation the hand's global orientation, the model's mean
shape) and its camera weak-perspective: a joint ``X`` of the hand (metres, wrist at the origin) lands at pixel
``scale * X[:2] + trans``. Unknowns (`HandClipUnknowns`): each frame's wrist rotation, its 15 finger joints'
rotations, ``log(scale)`` and ``trans``. The residuals are the body's clip fit's (`clip`), in the same units and
with the same standard deviations (`ClipConfig`):

* the 21 keypoints' reprojection, pixels over ``keypoint_sigma_px``, by confidence, robust (Cauchy);
* the 20 bones' directions against the 3D landmarks' (in the camera's axes), radians, by confidence, robust;
* the fingers within their range, bending as hinges, and their rotations from rest (`clip`'s priors);
* motion: the 21 keypoints' accelerations in the camera frame (the wrist at depth ``focal_length / scale`` on the
  ray through its pixel: a weak-perspective camera is a pinhole's view of a hand whose depth is small against its
  distance), m/s^2, and the 16 rotations' angular accelerations, rad/s^2.

Frames where the hand is not ``found`` hold their start and weigh nothing. Solved by `ClipLevenbergMarquardt`,
preconditioned by the Gauss-Newton matrix's blocks (`banded`; 51 unknowns a frame): each frame's, of its own
residuals (the fingertips' blended skinning left out), and the accelerations' between frames one and two apart.
Work and memory are linear in the number of frames.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from jaxmocap.integrate import banded, mat3
from jaxmocap.integrate import keypoints as keypoint_map
from jaxmocap.integrate.clip import HAND_BONES, ClipConfig, inverse3, motion_residuals, prior_sigma_rad
from jaxmocap.integrate.clip_solver import ClipLevenbergMarquardt, Step
from jaxmocap.integrate.hand_fit import hand_keypoint_model, side_indices
from jaxmocap.integrate.keypoints import KeypointModel, keypoints_cm
from jaxmocap.integrate.least_squares import bend_of, log1p_ratio
from smplx_jax import SIDES, BodyModel

JOINTS = 16  # the wrist, then the 15 finger joints in SMPL-X's order
UNKNOWNS = 3 * JOINTS + 3  # a frame's: the rotations' increments, then the camera's
# The body's units and standard deviations; fewer conjugate-gradient steps per step than the body's, as the
# preconditioner here holds each frame's whole Gauss-Newton block (the body's leaves the shape's coupling out).
HAND_CLIP = ClipConfig(cg_iterations=4)


class HandClipUnknowns(NamedTuple):
    """What `fit_hand_clip` solves for, ``T`` frames (``betas``: a placeholder for the solver's shared unknowns;
    the hand keeps the model's mean shape)."""

    pose_rotvecs: Float[Array, "T 16 3"]  # the wrist's rotation (the hand's global orientation), then the fingers'
    transl: Float[Array, "T 3"]  # the camera: log(pixels per metre), then the wrist's pixel
    betas: Float[Array, "1"]


class HandClipData(NamedTuple):
    """The observations and constants of one hand's clip (`hand_clip_problem`)."""

    km: KeypointModel  # the side's 21 keypoints (`hand_fit.hand_keypoint_model`)
    left: Bool[Array, ""]
    target: Float[Array, "T 21 2"]  # pixels
    confidence: Float[Array, "T 21"]  # 0: missing
    sigma: Float[Array, "T 21"]  # pixels
    directions: Float[Array, "T 20 3"]  # unit, camera axes
    direction_weight: Float[Array, "T 20"]  # 0: missing
    found: Float[Array, "T"]
    start: HandClipUnknowns
    focal_length: Float[Array, ""]
    principal_point: Float[Array, "2"]
    fps: Float[Array, ""]


class HandClipResult(NamedTuple):
    """`fit_hand_clip`'s result, ``T`` leading: the hand as `hand_fit.HandFit` holds it, whether the solve
    converged, its steps."""

    global_orient: Float[Array, "T 3"]
    hand_pose: Float[Array, "T 15 3"]
    camera_scale: Float[Array, "T"]
    camera_trans: Float[Array, "T 2"]
    reprojection_error_px: Float[Array, "T"]
    converged: Bool[Array, ""]
    steps: Int[Array, ""]


def _full_pose(left, pose: Float[Array, "16 3"]) -> Float[Array, "55 3"]:
    """The body at rest with the hand's wrist and fingers at ``pose``."""
    ids = side_indices(left, pose.dtype)
    return jnp.zeros((55, 3), pose.dtype).at[ids.wrist].set(pose[0]).at[ids.fingers].set(pose[1:])


def _hand_points(km: KeypointModel, left, pose: Float[Array, "16 3"]) -> Float[Array, "21 3"]:
    """The hand's 21 keypoints, metres, wrist at the origin, in the camera's axes."""
    x = keypoints_cm(km, _full_pose(left, pose), jnp.zeros(km.body.num_betas, pose.dtype)).T
    return x - x[0]


def _linearized_points(km: KeypointModel, left, pose: Float[Array, "16 3"]
                       ) -> tuple[Float[Array, "21 3"], Float[Array, "63 48"]]:
    """`_hand_points` and their Jacobian in the rotations' local increments (`keypoints.pose_jacobian`)."""
    ids = side_indices(left, pose.dtype)
    lin = keypoint_map.in_tangent(keypoint_map.linearize(km, _full_pose(left, pose),
                                                         jnp.zeros(km.body.num_betas, pose.dtype)))
    jacobian = keypoint_map.pose_jacobian(km, lin)[:, :, jnp.concatenate([ids.wrist[None], ids.fingers])]
    jacobian = jacobian - jacobian[:, :1]  # (3, 21, 16, 3), relative to the wrist
    return lin.x.T - lin.x.T[0], jnp.moveaxis(jacobian, 0, 1).reshape(63, 3 * JOINTS)


def _bone_units(x: Float[Array, "21 3"]) -> Float[Array, "20 3"]:
    a, b = (np.asarray(side) for side in zip(*HAND_BONES))
    bone = x[b] - x[a]
    return bone / jnp.sqrt(jnp.maximum(jnp.sum(bone * bone, -1, keepdims=True), 1e-12))


def _errors(x, camera, obs, config: ClipConfig):
    """One frame's reprojection and direction errors, each over its standard deviation."""
    target, sigma, directions = obs[0], obs[2], obs[3]
    pixels = jnp.exp(camera[0]) * x[:, :2] + camera[1:]
    return (pixels - target) / sigma[:, None], (_bone_units(x) - directions) / np.radians(config.direction_sigma_deg)


def _cauchy(errors, config: ClipConfig):
    return tuple(jnp.sum(e * e, -1) / config.cauchy**2 for e in errors)


def _frame_residuals(pose, camera, x, obs, data: HandClipData, config: ClipConfig, weights=None):
    """One frame's residuals (all but the motion) of its unknowns and its keypoints ``x`` (`_hand_points`);
    ``weights`` Cauchy's of its keypoints and bones held (None: the robust errors themselves)."""
    _, confidence, _, _, direction_weight, found, start_pose, start_camera = obs
    errors = _errors(x, camera, obs, config)
    robust = ([jnp.sqrt(log1p_ratio(u)) for u in _cauchy(errors, config)] if weights is None
              else [jnp.sqrt(w) for w in weights])
    reprojection = (jnp.sqrt(confidence * found) * robust[0])[:, None] * errors[0]
    direction = (jnp.sqrt(direction_weight * found) * robust[1])[:, None] * errors[1]
    limits = jax.nn.relu(bend_of(_full_pose(data.left, pose))) / np.radians(config.limit_sigma_deg)
    prior = pose[1:] / prior_sigma_rad(config)[25:40]
    hold = (1.0 - found) * jnp.concatenate([(pose - start_pose).ravel(), camera - start_camera])
    return jnp.concatenate([reprojection.ravel(), direction.ravel(), limits, prior.ravel(), hold])


def _observed(data: HandClipData):
    """Each frame's observations, frames leading (what `_frame_residuals` takes as ``obs``)."""
    return (data.target, data.confidence, data.sigma, data.directions, data.direction_weight, data.found,
            data.start.pose_rotvecs, data.start.transl)


def _camera_points(x: Float[Array, "21 3"], camera: Float[Array, "3"], data: HandClipData) -> Float[Array, "21 3"]:
    """The keypoints in the camera frame, metres: the wrist at depth ``focal / scale`` on its pixel's ray."""
    depth = data.focal_length / jnp.exp(camera[0])
    wrist = jnp.concatenate([(camera[1:] - data.principal_point) * depth / data.focal_length, depth[None]])
    return x + wrist


def _motion_rows(found: Float[Array, "T"]) -> Float[Array, "T 21"]:
    """1 where a frame and both its neighbours hold the hand (its accelerations are residuals)."""
    middle = found[:-2] * found[1:-1] * found[2:] if found.shape[0] > 2 else found[:0]
    zero = jnp.zeros_like(found[:1])
    rows = jnp.concatenate([zero, middle, zero])[: found.shape[0]]
    return jnp.repeat(rows[:, None], 21, 1)


def residuals(y: HandClipUnknowns, data: HandClipData, config: ClipConfig,
              weighed_at: HandClipUnknowns | None = None) -> tuple[Float[Array, "T F"], Float[Array, "T M"]]:
    """Every residual of the clip (module docstring); with ``weighed_at``, the robust errors scaled by Cauchy's
    weights there (iteratively reweighted, as `clip.residuals`)."""
    weights = None if weighed_at is None else cauchy_weights(weighed_at, data, config)
    x = jax.vmap(lambda p: _hand_points(data.km, data.left, p))(y.pose_rotvecs)
    frames = jax.vmap(lambda p, c, x, o, w: _frame_residuals(p, c, x, o, data, config, w),
                      in_axes=(0, 0, 0, 0, None if weights is None else 0))(
        y.pose_rotvecs, y.transl, x, _observed(data), weights)
    moving = jax.vmap(lambda x, c: _camera_points(x, c, data))(x, y.transl)
    return frames, motion_residuals(moving, y.pose_rotvecs, _motion_rows(data.found), data.fps, config)


def _weights(x, camera, obs, config: ClipConfig):
    """Cauchy's weight ``1 / (1 + u)`` of one frame's keypoints (21,) and bones (20,), its keypoints at ``x``."""
    return tuple(1.0 / (1.0 + u) for u in _cauchy(_errors(x, camera, obs, config), config))


def cauchy_weights(y: HandClipUnknowns, data: HandClipData, config: ClipConfig):
    """Cauchy's weight ``1 / (1 + u)`` of each frame's keypoints ``(T, 21)`` and bones ``(T, 20)`` at ``y``."""
    return jax.vmap(lambda p, c, o: _weights(_hand_points(data.km, data.left, p), c, o, config))(
        y.pose_rotvecs, y.transl, _observed(data))


class HandBlocks(NamedTuple):
    """The Gauss-Newton matrix's blocks (`hand_preconditioner`): each frame's 51 unknowns, coupled to the frames
    beside it; a `clip_solver.Preconditioner`."""

    system: banded.Banded

    def diagonal(self) -> Step:
        d = jnp.diagonal(self.system.diagonal, axis1=-2, axis2=-1)
        return Step(d[:, :3 * JOINTS].reshape(-1, JOINTS, 3), d[:, 3 * JOINTS:], jnp.ones(1, d.dtype))

    def damped_inverse(self, shift: Step):
        frames = shift.pose.shape[0]
        rows = jnp.concatenate([shift.pose.reshape(frames, -1), shift.transl], 1)
        (factor,) = banded.factor([self.system._replace(diagonal=self.system.diagonal + jax.vmap(jnp.diag)(rows))])

        def apply(v: Step) -> Step:
            (x,) = banded.solve((factor,), (jnp.concatenate([v.pose.reshape(frames, -1), v.transl], 1),))
            return Step(x[:, :3 * JOINTS].reshape(frames, JOINTS, 3), x[:, 3 * JOINTS:], v.betas)

        return apply


def hand_preconditioner(y: HandClipUnknowns, data: HandClipData, config: ClipConfig) -> HandBlocks:
    """Blocks of the Gauss-Newton matrix of the residuals reweighted at ``y`` (`residuals`): each frame's, of its
    own residuals (the fingertips' blended skinning left out), and the accelerations' between frames one and two
    apart, from each frame's keypoints' Jacobian (the rotations' turns taken as their increments, as
    `clip.preconditioner`)."""
    zero = jnp.zeros(UNKNOWNS, y.transl.dtype)

    def frame(pose, camera, obs):
        x, dx = _linearized_points(data.km, data.left, pose)
        w = _weights(x, camera, obs, config)
        to_theta = inverse3(mat3.left_jacobian(pose))  # each axis-angle's change per local increment

        def of(step):  # the frame's residuals and keypoints, to first order in the step
            turn = step[:3 * JOINTS]
            moved = pose + jnp.einsum("jab,jb->ja", to_theta, turn.reshape(JOINTS, 3)), camera + step[3 * JOINTS:]
            points = x + (dx @ turn).reshape(21, 3)
            return _frame_residuals(*moved, points, obs, data, config, w), _camera_points(points, moved[1], data)
        residual, points = jax.jacfwd(of)(zero)
        return residual.T @ residual, points.reshape(-1, UNKNOWNS)

    own, points = jax.vmap(frame)(y.pose_rotvecs, y.transl, _observed(data))
    rows = _motion_rows(data.found)[:, 0]
    turn = jnp.diag((jnp.arange(UNKNOWNS) < 3 * JOINTS).astype(own.dtype)) * (
        data.fps**2 / config.angular_acceleration_sigma) ** 2
    move = (data.fps**2 / config.acceleration_sigma) ** 2

    def pairs(by):  # [t]: the accelerations' metric between frames t + by and t (zero past the end)
        if points.shape[0] <= by:
            return jnp.zeros_like(own)
        products = move * jnp.einsum("tki,tkj->tij", points[by:], points[:points.shape[0] - by]) + turn
        return jnp.concatenate([products, jnp.zeros_like(own[:by])])

    def shifted(r, by):  # r[t + by] at t, zero past either end
        return jnp.roll(r, -by) * ((jnp.arange(r.shape[0]) + by >= 0) & (jnp.arange(r.shape[0]) + by < r.shape[0]))

    # the acceleration of frame t is rows[t] (x[t-1] - 2 x[t] + x[t+1]): frames t - 1, t, t + 1 with (1, -2, 1)
    diagonal = own + (shifted(rows, 1) + 4 * rows + shifted(rows, -1))[:, None, None] * pairs(0)
    first = (-2 * (shifted(rows, 1) + rows))[:, None, None] * pairs(1)
    second = shifted(rows, 1)[:, None, None] * pairs(2)
    return HandBlocks(banded.Banded(diagonal, first, second))


def hand_clip_problem(model: BodyModel | KeypointModel, side: str | Bool[ArrayLike, ""],
                      keypoints: Float[ArrayLike, "T 21 3"],
                      start: HandClipUnknowns, *, focal_length, principal_point, fps,
                      keypoint_sigma_px: Float[ArrayLike, "T 21"], directions: Float[ArrayLike, "T 20 3"],
                      direction_weight: Float[ArrayLike, "T 20"], found: Bool[ArrayLike, "T"] | None = None
                      ) -> HandClipData:
    """`fit_hand_clip`'s data (its arguments; ``model`` or the side's keypoint model already built, which a traced
    ``side``, true for the left hand, needs)."""
    dtype = start.transl.dtype
    keypoints = jnp.asarray(keypoints)
    finite = jnp.all(jnp.isfinite(keypoints), -1)
    confidence = jnp.where(finite & (keypoints[..., 2] > 0), keypoints[..., 2], 0.0).astype(dtype)
    target = jnp.where(finite[..., None], keypoints[..., :2], 0.0).astype(dtype)
    found = jnp.sum(confidence > 0, -1) > 0 if found is None else jnp.asarray(found)
    km = model if isinstance(model, KeypointModel) else hand_keypoint_model(model, side)
    left = jnp.asarray(side == "left") if isinstance(side, str) else jnp.asarray(side, bool)
    return HandClipData(km, left, target, confidence, jnp.asarray(keypoint_sigma_px, dtype),
                        jnp.asarray(directions, dtype), jnp.asarray(direction_weight, dtype), found.astype(dtype),
                        start, jnp.asarray(focal_length, dtype), jnp.asarray(principal_point, dtype),
                        jnp.asarray(fps, dtype))


def solve_hand_clip(start: HandClipUnknowns, data: HandClipData, config: ClipConfig | None = None,
                    adjoint: optx.AbstractAdjoint | None = None) -> HandClipResult:
    """The clip fit of `hand_clip_problem`'s data from ``start`` (``config`` default `HAND_CLIP`)."""
    config = config or HAND_CLIP
    with jax.default_matmul_precision("highest"):
        solver = ClipLevenbergMarquardt(tolerance=config.tolerance_per_frame * jnp.maximum(jnp.sum(data.found), 1.0),
                                        fit_shared=False, cg_iterations=config.cg_iterations)
        cost = jax.tree_util.Partial(residuals, config=config)
        options = dict(preconditioner=jax.tree_util.Partial(hand_preconditioner, config=config), reweighted=cost)
        solution = optx.least_squares(cost, solver, start, data, options=options, max_steps=config.iterations,
                                      throw=False, adjoint=optx.ImplicitAdjoint() if adjoint is None else adjoint)
        y = solution.value

        def error(pose, camera, target, confidence):
            x = _hand_points(data.km, data.left, pose)
            distance = jnp.linalg.norm(jnp.exp(camera[0]) * x[:, :2] + camera[1:] - target, axis=-1)
            seen = confidence > 0
            return jnp.sum(jnp.where(seen, distance, 0.0)) / jnp.maximum(jnp.sum(seen), 1)

        return HandClipResult(y.pose_rotvecs[:, 0], y.pose_rotvecs[:, 1:], jnp.exp(y.transl[:, 0]), y.transl[:, 1:],
                              jax.vmap(error)(y.pose_rotvecs, y.transl, data.target, data.confidence),
                              solution.result == optx.RESULTS.successful, solution.stats["num_steps"])


def hand_clip_start(global_orient: Float[ArrayLike, "T 3"], hand_pose: Float[ArrayLike, "T 15 3"],
                    camera_scale: Float[ArrayLike, "T"], camera_trans: Float[ArrayLike, "T 2"]) -> HandClipUnknowns:
    """The unknowns of frames fitted one by one (`hand_fit.HandFit`'s arrays): the start of `fit_hand_clip`."""
    global_orient = jnp.asarray(global_orient)
    dtype = global_orient.dtype
    pose = jnp.concatenate([global_orient[:, None], jnp.asarray(hand_pose, dtype)], 1)
    camera = jnp.concatenate([jnp.log(jnp.maximum(jnp.asarray(camera_scale, dtype), 1e-6))[:, None],
                              jnp.asarray(camera_trans, dtype)], 1)
    return HandClipUnknowns(pose, camera, jnp.zeros(1, dtype))


def fit_hand_clip(model: BodyModel, side: str, keypoints: Float[ArrayLike, "T 21 3"], start: HandClipUnknowns, *,
                  focal_length, principal_point, fps, keypoint_sigma_px: Float[ArrayLike, "T 21"],
                  directions: Float[ArrayLike, "T 20 3"], direction_weight: Float[ArrayLike, "T 20"],
                  found: Bool[ArrayLike, "T"] | None = None, config: ClipConfig | None = None) -> HandClipResult:
    """Fit one hand's clip (module docstring). ``keypoints (T, 21, 3)``: OpenPose hand order, pixels and a
    confidence (0, NaN or inf: missing); ``start`` each frame's start (`hand_clip_start`); ``focal_length`` and
    ``principal_point`` the lens, pixels; ``fps`` the frame rate (0: unrelated images); ``keypoint_sigma_px`` each
    keypoint's detector noise; ``directions`` and ``direction_weight``: the observed unit direction of each of
    `clip.HAND_BONES` in the camera's axes and its confidence; ``found`` where the hand is (default: where any
    keypoint is). Pure: works under `jax.jit` and `jax.grad` (implicit differentiation of the optimum)."""
    if side not in SIDES:
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    data = hand_clip_problem(model, side, keypoints, start, focal_length=focal_length,
                             principal_point=principal_point, fps=fps, keypoint_sigma_px=keypoint_sigma_px,
                             directions=directions, direction_weight=direction_weight, found=found)
    return solve_hand_clip(start, data, config)
