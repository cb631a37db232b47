"""Optimization integration: fit SMPL-X (pose, both hands, shape, camera) to 2D keypoints.

    result = fit_frame(model, keypoints, init)     # one frame: keypoints (67, 3) BODY_25, left, right hand; x, y, conf
    result = fit(model, keypoints, init=params)    # (T, 67, 3): vmap of the same fit, padded to fixed batch sizes

Each frame is a robust least-squares problem solved by `optimistix.least_squares` (`levenberg_marquardt.solve`):
confidence-weighted Cauchy-robust reprojection of the 67 keypoints, a prior that keeps each joint near the initial
pose (weaker for hands; fingers as hinges), shape L2 and the joint limits of elbows, knees and fingers. The camera
is a pinhole of known focal length (``focal_length`` and ``principal_point``: the body's depth and perspective are
fitted, ``params.transl`` is its origin in the camera frame) or weak perspective (no focal length). `fit_frame` is
pure: it works under `jax.jit`, `jax.vmap` and `jax.grad`; gradients of the fitted parameters with respect to the
keypoints, their confidences, the start and the camera come from implicit differentiation. `fit` runs the same
steps in jitted batches padded to a few sizes (`BUCKETS`), spread over all devices, in rounds that leave out the
frames already converged: a batch does not wait on its slowest frame.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from jaxmocap.buckets import map_in_buckets
from jaxmocap.compile_cache import disk_jit
from jaxmocap.integrate import least_squares, levenberg_marquardt
from jaxmocap.integrate.camera import weak_perspective_from_points, weak_perspective_least_squares
from jaxmocap.integrate.keypoints import KeypointModel, keypoint_model, keypoints_cm, params_of
from jaxmocap.integrate.least_squares import prior_weights
from jaxmocap.sharding import shard_frames
from smplx_jax import BodyModel, SMPLXParams, constants

BUCKETS = (1, 8, 32, 64)  # padded batch sizes; longer inputs run in chunks of 64 (faster here than 1024: cache)
MIN_KEYPOINTS = 3  # fewer visible keypoints: the frame has no person to fit
# The default cap on steps: well above the steps frames take to converge in float32 and float64, from real and
# synthetic starts (bench/convergence.py; docs/BENCHMARKS.md, "The default step cap").
ITERATIONS = 400
ROUND_STEPS = 50  # `fit` steps its frames in rounds of at most this many (`_solve_frames`)
SOLVE_FRAMES = 1024  # `fit` solves at most this many frames at a time (their solver states are held in memory)

OK, NO_KEYPOINTS, FAILED = 0, 1, 2  # FitResult.status

FitConfig = least_squares.SolverConfig


class FitResult(NamedTuple):
    """A fit: one frame from `fit_frame`, a leading axis T from `fit`. ``status``: 0 fitted, 1 too few
    keypoints, 2 numerical failure; frames with a non-zero status hold the initial parameters and camera.
    ``converged``: the solve met its stopping rule (`levenberg_marquardt.LevenbergMarquardt`) rather than its step cap
    (``iterations``); implicit gradients are exact where it did.
    ``camera_scale``, ``camera_trans``: the weak-perspective projection of the fitted body (``transl`` included;
    docs/formats.md, "Coordinates and cameras"), for a pinhole camera the one closest to its projection.
    ``reprojection_error_px``: the fit's own (perspective for a pinhole camera). ``steps``: the solver's steps taken
    (at most ``iterations``; fewer where it converged, or `levenberg_marquardt.stalled`)."""

    params: SMPLXParams
    camera_scale: Float[Array, "*T"]
    camera_trans: Float[Array, "*T 2"]
    status: Int[Array, "*T"]
    reprojection_error_px: Float[Array, "*T"]  # mean pixel distance over keypoints with confidence > 0 (0 if none)
    initial_reprojection_error_px: Float[Array, "*T"]
    converged: Bool[Array, "*T"]
    steps: Int[Array, "*T"]

    @property
    def valid(self):
        return self.status == OK


def openpose_keypoint_model(model: BodyModel) -> KeypointModel:
    """The fit's constants for the 67 OpenPose keypoints."""
    return keypoint_model(model, constants.OPENPOSE67_FROM_SMPLX)


def default_pose(dtype=jnp.float32) -> Float[Array, "55 3"]:
    """The fit's default start: facing the camera upright in image axes (y down: pi about x), arms lowered,
    elbows slightly bent, flat hands."""
    theta = np.zeros((55, 3), np.float32)
    theta[0] = (np.pi, 0, 0)
    theta[16], theta[17] = (0, 0, -1.1), (0, 0, 1.1)  # shoulders
    theta[18], theta[19] = (0, -0.3, 0), (0, 0.3, 0)  # elbows
    return jnp.asarray(theta, dtype)


def fit_one(km: KeypointModel, keypoints, pose, betas, camera, lens, config: FitConfig, free=None,
            fit_betas=None, adjoint=None) -> FitResult:
    """`fit_frame` of one frame from its full pose ``(55, 3)`` with its keypoint model ``km`` made beforehand
    (`openpose_keypoint_model`); ``camera`` (3,) or None (fitted to the start); ``lens`` (`lens_arrays`):
    (1 / focal length, principal point), 1 / focal length 0 for weak perspective; ``free`` (55,) 1 for the joints
    fitted (default all), ``fit_betas`` 1 to fit the shape (default); ``adjoint`` as in `fit_frame`.
    Matrix products in full float32 on every device: a GPU's default TF32 ends the fit worse at the same speed
    (docs/BENCHMARKS.md, "On a GPU")."""
    with jax.default_matmul_precision("highest"):
        return _fit_one(km, keypoints, pose, betas, camera, lens, config, free, fit_betas, adjoint)


def _fit_one(km, keypoints, pose, betas, camera, lens, config, free, fit_betas, adjoint) -> FitResult:
    problem, start, camera = _problem(km, keypoints, pose, betas, camera, lens, config, free, fit_betas)
    solution = levenberg_marquardt.solve(problem, start, config, adjoint)
    converged = solution.result == optx.RESULTS.successful
    solved = converged | (solution.result == optx.RESULTS.nonlinear_max_steps_reached)
    return _result(problem, start, camera, solution.value, converged, solved, solution.stats["num_steps"])


def _problem(km, keypoints, pose, betas, camera, lens, config, free, fit_betas
             ) -> tuple[least_squares.Problem, least_squares.Unknowns, Float[Array, "3"]]:
    """One frame's least-squares problem, its start and the start's camera ``(scale, tx, ty)``."""
    dtype = pose.dtype
    inv_focal, center = lens
    finite = jnp.all(jnp.isfinite(keypoints), axis=-1)
    conf = jnp.where(finite & (keypoints[:, 2] > 0), keypoints[:, 2], 0.0)
    target = jnp.where(finite[:, None], keypoints[:, :2], 0.0)
    if camera is None:
        scale, trans = weak_perspective_from_points(keypoints_cm(km, pose, betas)[:2].T, target, conf)
        camera = jnp.concatenate([scale[None], trans])
    sref = jnp.where(jnp.isfinite(camera[0]) & (camera[0] > 0), camera[0], 1.0)
    problem = least_squares.Problem(km, target, conf, pose, betas, jnp.asarray(prior_weights(config), dtype), sref,
                                    jnp.ones(55, dtype) if free is None else free,
                                    jnp.ones((), dtype) if fit_betas is None else fit_betas, inv_focal, center)
    return problem, least_squares.Unknowns(pose, betas, jnp.concatenate([jnp.log(sref)[None], camera[1:]])), camera


def _result(problem: least_squares.Problem, start: least_squares.Unknowns, camera, out: least_squares.Unknowns,
            converged, solved, steps) -> FitResult:
    """The `FitResult` of a solve of ``problem`` from ``start`` (camera ``(scale, tx, ty)``) that ended at ``out``."""
    km, target, conf, pose, betas = problem.km, problem.target, problem.conf, problem.pose0, problem.betas0
    inv_focal, center = problem.inv_focal, problem.center
    seen = conf > 0

    def reprojection_error(pixels):
        err = jnp.linalg.norm(pixels.T - target, axis=-1)
        return jnp.sum(jnp.where(seen, err, 0.0)) / jnp.maximum(jnp.sum(seen), 1)

    err0 = reprojection_error(least_squares.project(keypoints_cm(km, pose, betas), start.camera, problem)[0])
    points = keypoints_cm(km, out.pose_rotvecs, out.betas)
    pixels = least_squares.project(points, out.camera, problem)[0]
    err = reprojection_error(pixels)
    scale, trans = jnp.exp(out.camera[0]), out.camera[1:]
    pinhole = inv_focal > 0
    transl = jnp.where(pinhole, jnp.append((trans - center) / scale, 1.0 / jnp.where(pinhole, inv_focal * scale, 1.0)),
                       0.0)
    weak_scale, weak_trans = weak_perspective_least_squares((points + transl[:, None])[:2].T, pixels.T, conf)
    scale, trans = jnp.where(pinhole, weak_scale, scale), jnp.where(pinhole, weak_trans, trans)
    enough = jnp.sum(seen) >= MIN_KEYPOINTS
    finite_out = jnp.all(jnp.array([jnp.all(jnp.isfinite(a)) for a in jax.tree.leaves(out)])) & jnp.isfinite(err)
    status = jnp.where(~enough, NO_KEYPOINTS, jnp.where(solved & finite_out, OK, FAILED)).astype(jnp.int32)
    keep = status == OK
    pick = functools.partial(jnp.where, keep)
    err0 = jnp.where(enough & jnp.isfinite(err0), err0, 0.0)
    params = params_of(pick(out.pose_rotvecs, pose), pick(out.betas, betas), km.body.num_expression)
    params = params.replace(transl=pick(transl, jnp.zeros_like(transl)))
    return FitResult(params, pick(scale, camera[0]), pick(trans, camera[1:]), status, pick(err, err0), err0,
                     keep & converged, jnp.asarray(steps, jnp.int32))


def lens_arrays(focal_length, principal_point, dtype):
    """`fit_one`'s ``lens``: ``(1 / focal length, principal point)``; zeros for weak perspective."""
    if focal_length is None:
        return jnp.zeros((), dtype), jnp.zeros(2, dtype)
    if principal_point is None:
        raise ValueError("principal_point is needed with focal_length")
    return 1.0 / jnp.asarray(focal_length, dtype), jnp.asarray(principal_point, dtype)


def fit_frame(model: BodyModel, keypoints: Float[Array, "67 3"], init: SMPLXParams, *,
              camera: Float[Array, "3"] | None = None, focal_length: float | Float[Array, ""] | None = None,
              principal_point: Float[Array, "2"] | None = None, iterations: int = ITERATIONS,
              config: FitConfig | None = None, adjoint: optx.AbstractAdjoint | None = None) -> FitResult:
    """Fit one frame's ``keypoints (67, 3)`` (pixels; confidence 0 or NaN/inf = missing) from ``init`` (one
    body; hand poses absolute; ``transl`` and ``expression`` ignored, the result has no expression).
    ``camera``: ``(scale, tx, ty)`` of the body's origin (``pixel = scale * x + t`` there) to start from, or None
    to fit it to the start's keypoints. ``focal_length`` (pixels) and ``principal_point`` (2,): a pinhole camera
    (``transl`` of the result is the body's origin in its frame, metres); None: weak perspective. ``iterations``:
    the cap on Levenberg-Marquardt steps; the solve stops earlier once converged (``FitResult.converged``).

    Pure and differentiable. Gradients with respect to the keypoints, their confidences, the start and the
    camera come from implicit differentiation (``adjoint`` None, `optimistix.ImplicitAdjoint`): the derivative of
    the optimum, exact where ``converged`` (an unseen keypoint's gradient is zero). Where a fit was cut short by
    its step cap, ``adjoint=optimistix.RecursiveCheckpointAdjoint()`` gives the derivative of what was computed,
    the steps themselves."""
    config = dataclasses.replace(config or FitConfig(), iterations=iterations)
    km = openpose_keypoint_model(model)
    pose = init.full_pose()
    lens = lens_arrays(focal_length, principal_point, pose.dtype)
    return fit_one(km, keypoints, pose, init.betas, camera, lens, config, adjoint=adjoint)


def _frames(fn, *args, in_axes=0):
    """``fn`` of one frame vmapped over the frames of ``args``, matrix products in full float32 (`fit_one`)."""
    with jax.default_matmul_precision("highest"):
        return jax.vmap(fn, in_axes=in_axes)(*args)


@disk_jit(static_argnames=("config", "fixed_shape"))
def _start_batch(km, keypoints, pose, betas, camera, free, lens, config: FitConfig, fixed_shape: bool = False):
    """A batch's problems (``km`` left out: one for all), starts, start cameras and solver states."""
    fit_betas = jnp.zeros((), pose.dtype) if fixed_shape else None

    def one(k, p, b, c, f):
        problem, start, c = _problem(km, k, p, b, c, lens, config, f, fit_betas)
        return problem._replace(km=None), start, c, levenberg_marquardt.initial_state(problem, start, config)

    return _frames(one, keypoints, pose, betas, camera, free, in_axes=(0, 0, 0, None if camera is None else 0, 0))


@disk_jit(static_argnames="config")
def _advance_batch(km, problem, y, state, until, config: FitConfig):
    """Each frame's solve resumed from ``state`` until it is `levenberg_marquardt.finished` or its step count
    reaches ``until`` (``config.iterations``: the most steps this takes): the points and the states."""
    def one(p, y, state, until):
        solution = levenberg_marquardt.solve(p._replace(km=km), y, config, resume=state, until=until)
        return solution.value, solution.state

    return _frames(one, problem, y, state, until)


@disk_jit
def _result_batch(km, problem, start, camera, y, converged, steps):
    return _frames(lambda p, s, c, y, ok, n: _result(p._replace(km=km), s, c, y, ok, True, n), problem, start,
                   camera, y, converged, steps)


def _rows(tree) -> int:
    return len(jax.tree.leaves(tree)[0])


def _solve_frames(km, frames, lens, config: FitConfig, fixed_shape: bool, progress) -> FitResult:
    """`fit` of at most `SOLVE_FRAMES` frames ``(keypoints, pose, betas, camera, free)``, in rounds of `ROUND_STEPS`
    steps: each round runs the frames still going in as few padded batches as hold them, so no batch waits on its
    slowest frame (a frame takes the steps it would alone, up to float32's rounding in batches of other sizes)."""
    def batches(fn, tree, keep=np.array):  # (kept before their real rows are cut: no slicing program per size)
        return map_in_buckets(lambda chunk, n: jax.tree.map(keep, fn(*shard_frames(chunk, _rows(chunk)))), tree,
                              BUCKETS)

    program = dataclasses.replace(config, iterations=ROUND_STEPS)  # a round's steps; the cap is this loop's
    problem, start, camera, state = batches(
        lambda *chunk: _start_batch(km, *chunk, lens, program, fixed_shape), frames)
    y = jax.tree.map(np.copy, start)  # (its rows are overwritten round by round; the start's error reads start)
    done = np.zeros(len(frames[0]), bool)
    while (active := np.flatnonzero(~done)).size:
        until = np.minimum(state.steps[active] + ROUND_STEPS, config.iterations).astype(np.int32)
        picked = jax.tree.map(lambda a: a[active], (problem, y, state))
        moved = batches(lambda *chunk: _advance_batch(km, *chunk, program), (*picked, until))
        for whole, part in zip(jax.tree.leaves((y, state)), jax.tree.leaves(moved)):
            whole[active] = part
        done[active] = levenberg_marquardt.finished(state)[active] | (state.steps[active] >= config.iterations)
        if progress is not None:
            progress(int(done[active].sum()))
    return batches(lambda *chunk: _result_batch(km, *chunk),
                   (problem, start, camera, y, state.converged, state.steps), keep=jnp.asarray)


def full_pose_of(params: SMPLXParams) -> Float[Array, "T 55 3"]:
    """The ``(T, 55, 3)`` axis-angles of batched ``params`` (`SMPLXParams.full_pose` per frame)."""
    return jax.vmap(SMPLXParams.full_pose)(params)


@functools.partial(jax.jit, static_argnames="num_expression")
def params_from_full_pose(pose, betas, num_expression: int) -> SMPLXParams:
    """Batched `SMPLXParams` from ``pose (T, 55, 3)`` and ``betas (T, B)`` (`keypoints.params_of` per frame;
    zero expression of ``num_expression`` components, zero translation)."""
    return jax.vmap(params_of, in_axes=(0, 0, None))(pose, betas, num_expression)


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
        focal_length: float | None = None, principal_point=None, iterations: int = ITERATIONS,
        config: FitConfig | None = None, fixed_shape: bool = False, free_joints=None, progress=None) -> FitResult:
    """Fit every frame of ``keypoints (T, 67, 3)`` (`fit_frame` vmapped). ``init``: batched `SMPLXParams` (T leading),
    default `default_pose` with mean shape; ``fixed_shape``: keep ``init.betas`` (fit pose and camera);
    ``free_joints`` (T, 55) bool: the joints each frame fits (the others keep ``init``'s; default all). Camera: given
    (both arrays), or fitted to the start; a pinhole of ``focal_length`` and ``principal_point`` or weak perspective
    (`fit_frame`). ``progress(n)`` is called after each round with the number of frames it finished. Runs in the
    model's precision (float32; a model loaded as float64 under ``jax.enable_x64`` fits in float64).
    """
    config = dataclasses.replace(config or FitConfig(), iterations=iterations)
    dtype = np.dtype(model.joint_template.dtype)
    keypoints = np.asarray(keypoints, dtype)
    if keypoints.ndim != 3 or keypoints.shape[1:] != (67, 3):
        raise ValueError(f"keypoints must have shape (T, 67, 3), got {keypoints.shape}")
    t = keypoints.shape[0]
    nb = model.num_betas
    if init is None:
        pose = np.broadcast_to(np.asarray(default_pose(dtype)), (t, 55, 3))
        betas = np.zeros((t, nb), dtype)
    else:
        pose = _check("init pose", full_pose_of(init), (t, 55, 3), dtype)
        betas = _check("init betas", init.betas, (t, nb), dtype)
    camera = None
    if camera_scale is not None:
        camera = np.concatenate([_check("camera_scale", camera_scale, (t,), dtype)[:, None],
                                 _check("camera_trans", camera_trans, (t, 2), dtype)], axis=1)
    free = np.ones((t, 55), dtype) if free_joints is None else _check("free_joints", free_joints, (t, 55), dtype)
    km = openpose_keypoint_model(model)
    lens = lens_arrays(focal_length, principal_point, dtype)
    frames = (keypoints, pose, betas, camera, free)
    parts = [_solve_frames(km, jax.tree.map(lambda a: a[i:i + SOLVE_FRAMES], frames), lens, config, fixed_shape,
                           progress) for i in range(0, t, SOLVE_FRAMES)]
    return parts[0] if len(parts) == 1 else jax.tree.map(lambda *p: jnp.concatenate(p), *parts)


__all__ = ["BUCKETS", "ITERATIONS", "FitConfig", "FitResult", "default_pose", "fit", "fit_frame",
           "openpose_keypoint_model"]
