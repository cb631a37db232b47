"""The solver of `least_squares`: Levenberg-Marquardt on the IRLS model of the cost, an optimistix solver.

Each step takes the model of the cost at the current point (`local_model`: the keypoint errors weighted by
Cauchy's ``rho' = conf / (1 + u)``, the analytic Jacobian of `keypoints` and of the projection, the priors),
solves ``(H + mu diag(H)) delta = -g`` and keeps the step if the cost falls; ``mu`` follows Nielsen's rule on the
ratio of the actual to the predicted decrease. A bending limit has no curvature until crossed: once a refused dense
step crossed one, the model holds its stiffness while the fit stays pressed against it (`least_squares.BEND_MARGIN`).
Steps move each rotation by a local increment, ``R_j <- exp(dphi_j) R_j`` (`retract`), not its axis-angle by
addition: a joint turned one way and its child turned back (a body turning on the spot, a neck and head) stay
aligned over a whole step, where axis-angle steps drift off that valley.
``SolverConfig.linear_solver`` says how the system is solved:

* ``"cholesky"`` (default): exactly, by a dense Cholesky factorisation over the unknowns the solve moves (some
  180: the joints of ``SolverConfig.joints``, the shape, the camera), on ``H + S``: ``S`` estimates from the steps
  taken the residuals' own curvature, which ``H`` leaves out (NL2SOL's structured secant, `updated_secant`; near
  the optimum the fingertips' curvature is several times the Gauss-Newton one, and Gauss-Newton steps crawl).
  Converges: the solve stops once a step at damping at most 1 predicts a relative decrease of the cost below
  ``SolverConfig.tolerance``, and reports it. Once refused steps raise the damping to its cap, the solve starts
  again at damping 1 without ``S``; the second time, it stops unconverged (`stalled`).
* ``"cg"``: ``cg_iterations`` steps of conjugate gradients, matrix-free, preconditioned by the 3x3 block of each
  joint, the shape's diagonal and the camera's block (`Blocks`): several times faster per step, inexact, for a
  fixed number of steps (the pipeline's and live capture's fits; the same stopping test, rarely met).

Both leave out the millimetre terms of blended skinning and pose blend shapes from ``H`` (cheaper, still
positive semi-definite); the gradient ``g`` is the cost's exact one. Gradients through `solve` come from
implicit differentiation (`optimistix.ImplicitAdjoint`, default) of the cost's optimality condition, exact where
the solve converged; ``adjoint=optimistix.RecursiveCheckpointAdjoint()`` differentiates the steps taken. Every
solve goes through `optimistix.least_squares` (`solve`), also one run in pieces between which a batch sets aside
its frames that are done (``resume`` and ``until``: `fitting.fit`).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
from jaxtyping import Array, Bool, Float, Int

from jaxmocap.integrate import keypoints, mat3
from jaxmocap.integrate.keypoints import KeypointModel, Linearization
from jaxmocap.integrate.least_squares import (
    BEND_LIMITS,
    BEND_MARGIN,
    Problem,
    SolverConfig,
    Unknowns,
    bend_of,
    cauchy_u,
    pose_and_shape,
    prior_quadratic,
    project,
    residuals,
)
from smplx_jax import rotations

MAX_DAMPING = 1e10  # beyond it steps are nothing; the damping stays finite
# The smallest diagonal entry a damped step scales by, relative to the largest: an unknown no term constrains still
# gets a positive damping (a floor far below any real entry's, which it leaves alone).
DIAGONAL_FLOOR = 1e-30
# The conjugate-gradient system's ridge, relative to each diagonal entry plus one: positive definite where the
# damping and a diagonal entry are both zero.
CG_RIDGE = 1e-9
MAX_GROWTH = 1024.0  # the most Nielsen's rule multiplies the damping by after a run of refused steps


def nielsen_damping(damping, growth, accept, ratio):
    """Nielsen's rule: after a step whose actual decrease is ``ratio`` times the predicted one, the damping and
    its growth factor. Taken: the damping times ``max(1/3, 1 - (2 ratio - 1)^3)``, the factor back to 2; refused:
    the damping times the factor, which doubles (to `MAX_GROWTH`). The damping is held at `MAX_DAMPING`."""
    return (jnp.minimum(jnp.where(accept, damping * jnp.maximum(1 / 3, 1 - (2 * ratio - 1) ** 3), damping * growth),
                        MAX_DAMPING),
            jnp.where(accept, 2.0, jnp.minimum(2.0 * growth, MAX_GROWTH)))


def _dot(a: Unknowns, b: Unknowns):
    return sum(jnp.sum(x * y) for x, y in zip(a, b))


def solved_joints(config: SolverConfig) -> np.ndarray:
    """The joints whose rotations the solve moves (`SolverConfig.joints`; all 55 by default), in order."""
    return np.arange(55) if config.joints is None else np.asarray(config.joints, np.int64)


class Blocks(NamedTuple):
    """A block diagonal of ``H``: the preconditioner of the ``"cg"`` solver."""

    pose: Float[Array, "3 3 55"]
    betas: Float[Array, "B"]
    camera: Float[Array, "C C"]

    def diagonal(self) -> Unknowns:
        return Unknowns(jnp.stack([self.pose[i, i] for i in range(3)], 1), self.betas, jnp.diagonal(self.camera))

    def damped_inverse(self, shift: Unknowns) -> Blocks:
        """The blocks of ``(blocks + diag(shift))^-1``."""
        eye = jnp.eye(3, dtype=self.betas.dtype)[:, :, None]
        camera = self.camera + jnp.diag(shift.camera)
        camera = mat3.inverse(camera[:, :, None])[:, :, 0] if camera.shape[0] == 3 else jnp.linalg.inv(camera)
        return Blocks(mat3.inverse(self.pose + shift.pose_rotvecs.T[:, None, :] * eye),
                      1.0 / (self.betas + shift.betas), camera)

    def mv(self, v: Unknowns) -> Unknowns:
        return Unknowns(mat3.matvec(self.pose, v.pose_rotvecs.T).T, self.betas * v.betas, self.camera @ v.camera)


def _data_blocks(lin: Linearization, scale, w, d: int, km: KeypointModel):
    """Diagonal blocks of ``J^T diag(w) J`` of the data term of a similarity camera: 3x3 per joint (from moments of
    the keypoints about it: one GEMM with ``reach ** 2``) and the shape diagonal."""
    x, p = lin.x, lin.p
    nk = w.shape[0]
    xx = (x[:, None, :] * x[None, :, :]).reshape(9, nk)
    mom = jnp.concatenate([w[None], w * x, w * xx]) @ km.reach2  # (13, 55)
    m0, m1, m2 = mom[0], mom[1:4], mom[4:].reshape(3, 3, 55)
    m1p = m1[:, None, :] * p[None, :, :]
    q = m2 - m1p - jnp.swapaxes(m1p, 0, 1) + m0 * (p[:, None, :] * p[None, :, :])  # sum w v v^T, v = x - p
    if d == 2:  # [v]x^T P^T P [v]x with P the projection to x, y
        z = jnp.zeros_like(m0)
        b_omega = jnp.stack([jnp.stack([q[2, 2], z, -q[0, 2]]), jnp.stack([z, q[2, 2], -q[1, 2]]),
                             jnp.stack([-q[0, 2], -q[1, 2], q[0, 0] + q[1, 1]])])
    else:
        b_omega = (q[0, 0] + q[1, 1] + q[2, 2]) * jnp.eye(3, dtype=x.dtype)[:, :, None] - q
    b_pose = (scale * scale) * mat3.matmul(jnp.swapaxes(lin.a, 0, 1), mat3.matmul(b_omega, lin.a))
    jb = lin.jb[:, : d * nk]
    b_betas = (scale * scale) * ((jb * jb) @ jnp.tile(w, d))
    return b_pose, b_betas


def _camera_block(w, dlogscale, depth):
    """``J^T diag(w) J`` of the camera (log scale, translation): ``dlogscale (D, K)`` the log scale's column."""
    d = dlogscale.shape[0]
    cross = jnp.sum(w * dlogscale / depth, 1)
    return jnp.concatenate([jnp.concatenate([jnp.sum(w * dlogscale * dlogscale)[None], cross])[None],
                            jnp.concatenate([cross[:, None], jnp.sum(w / depth**2) * jnp.eye(d, dtype=w.dtype)], 1)])


class LocalModel(NamedTuple):
    """The IRLS model of the cost at one point, masked to the unknowns the solve moves: the exact ``gradient``,
    ``v -> H v`` and ``H``'s diagonal; ``dense`` is ``H`` over `_flat` (``"cholesky"``), ``blocks`` its block
    diagonal (``"cg"``)."""

    gradient: Unknowns
    hessian: Callable[[Unknowns], Unknowns]
    diagonal: Unknowns
    dense: Float[Array, "n n"] | None
    blocks: Blocks | None


def _prior_blocks(pose, betas, camera, problem: Problem, config: SolverConfig, stiff) -> tuple[Unknowns, Blocks]:
    """The priors' gradient and Gauss-Newton Hessian in the local increments of the rotations: the axis-angle
    moves by ``J_l(theta)^-1 dphi``, so a joint's diagonal block ``D`` becomes ``J_l^-T D J_l^-1``."""
    gradient, hessian = prior_quadratic(pose, betas, camera, problem, config, stiff)
    to_theta = mat3.inverse(jnp.transpose(mat3.left_jacobian(pose), (1, 2, 0)))  # (3, 3, 55)
    pose_block = mat3.matmul(jnp.swapaxes(to_theta, 0, 1), hessian.pose_rotvecs.T[:, None] * to_theta)
    c = camera.shape[0]
    return (gradient._replace(pose_rotvecs=mat3.matvec_t(to_theta, gradient.pose_rotvecs.T).T),
            Blocks(pose_block, hessian.betas, jnp.zeros((c, c), camera.dtype)))


def local_model(y: Unknowns, problem: Problem, config: SolverConfig, stiff: Bool[Array, "L"] | None = None
                ) -> LocalModel:
    """The model at ``y`` in the local increments of the rotations (``R_j <- exp(dphi_j) R_j``, `retract`);
    ``stiff``: the bending limits whose stiffness it holds just inside them too (`prior_quadratic`)."""
    d = problem.target.shape[1]
    km, joints = problem.km, solved_joints(config)
    pose, betas = pose_and_shape(y, problem)
    lin = keypoints.in_tangent(keypoints.linearize(km, pose, betas))
    scale = jnp.exp(y.camera[0])
    points, depth = project(lin.x, y.camera, problem)
    r = points - problem.target.T
    w = problem.conf / (1.0 + cauchy_u(r, problem, config))
    gain = scale / depth  # d points / d x[:D]
    slope = problem.inv_focal * (points - problem.center[:, None])  # d points / d x[2] = -gain * slope

    def image(dx):  # (3, K, ...) -> (D, K, ...)
        extra = (None,) * (dx.ndim - 2)
        return gain[(...,) + extra] * (dx[:d] - slope[(...,) + extra] * dx[2][None])

    dlogscale = image(lin.x)
    moving = np.zeros(55, np.float32)
    moving[joints] = 1.0
    mask = Unknowns(jnp.broadcast_to((problem.free * moving)[:, None], pose.shape),
                    jnp.broadcast_to(problem.fit_betas, betas.shape), jnp.ones_like(y.camera))
    prior_gradient, prior = _prior_blocks(pose, betas, y.camera, problem, config, stiff)

    def jv(v: Unknowns):  # (D, K)
        dx = keypoints.jvp(km, lin, v.pose_rotvecs * mask.pose_rotvecs, v.betas * mask.betas, exact=False)
        return image(dx) + v.camera[0] * dlogscale + v.camera[1:, None] / depth

    def jtu(u, exact: bool) -> Unknowns:
        gu = gain * u
        padded = jnp.concatenate([gu, jnp.zeros((3 - d,) + u.shape[1:], u.dtype)])
        padded = padded.at[2].add(-jnp.sum(gu * slope, 0))
        dpose, dbetas = keypoints.vjp(km, lin, padded, exact=exact)
        return Unknowns(dpose, dbetas, jnp.concatenate([jnp.sum(u * dlogscale)[None], jnp.sum(u / depth, 1)]))

    def masked(tree):
        return jax.tree.map(jnp.multiply, tree, mask)

    def hessian(v: Unknowns) -> Unknowns:
        return masked(jax.tree.map(jnp.add, jtu(w * jv(v), False), prior.mv(v)))

    gradient = masked(jax.tree.map(jnp.add, jtu(w * r, True), prior_gradient))
    if config.linear_solver == "cg":
        b_pose, b_betas = _data_blocks(lin, scale, w / depth**2, d, km)
        eye = jnp.eye(3, dtype=r.dtype)[:, :, None]
        blocks = Blocks(jnp.where(mask.pose_rotvecs[:, 0] > 0, b_pose + prior.pose, eye),
                        jnp.where(mask.betas > 0, b_betas + prior.betas, 1.0),
                        _camera_block(w, dlogscale, depth))
        return LocalModel(gradient, hessian, blocks.diagonal(), None, blocks)
    nk = r.shape[1]
    shape = jnp.concatenate([(keypoints.pose_jacobian(km, lin)[:, :, joints]
                              * mask.pose_rotvecs[joints][None, None]).reshape(3, nk, -1),
                             lin.jb.reshape(-1, 3, nk).transpose(1, 2, 0) * problem.fit_betas], axis=-1)
    jacobian = jnp.concatenate([image(shape), dlogscale[..., None], jnp.broadcast_to(
        jnp.eye(d, dtype=r.dtype)[:, None] / depth[None, :, None], (d, nk, d))], axis=-1)  # (D, K, n)
    fixed = 1.0 - _flat(mask, config)
    m = len(joints)
    prior_dense = jax.scipy.linalg.block_diag(
        jnp.einsum("abj,jk->jakb", prior.pose[:, :, joints], jnp.eye(m, dtype=r.dtype)).reshape(3 * m, 3 * m),
        jnp.diag(prior.betas), prior.camera)
    dense = (jnp.einsum("dkn,k,dkm->nm", jacobian, w, jacobian) + prior_dense) \
        * (1.0 - fixed)[:, None] * (1.0 - fixed)[None, :] + jnp.diag(fixed)
    diagonal = _unflat(jnp.diag(dense) * (1.0 - fixed), y, config)
    return LocalModel(gradient, hessian, diagonal, dense, None)


def _flat(y: Unknowns, config: SolverConfig) -> Float[Array, "n"]:
    """The unknowns the dense system holds: the rotations of `solved_joints`, the shape, the camera."""
    return jnp.concatenate([y.pose_rotvecs[solved_joints(config)].reshape(-1), y.betas, y.camera])


def _unflat(flat: Float[Array, "n"], like: Unknowns, config: SolverConfig) -> Unknowns:
    """`_flat`'s inverse, zero for the joints the solve does not move."""
    joints = solved_joints(config)
    m, b = 3 * len(joints), like.betas.shape[0]
    return Unknowns(jnp.zeros_like(like.pose_rotvecs).at[joints].set(flat[:m].reshape(-1, 3)), flat[m:m + b],
                    flat[m + b:])


def _step(model: LocalModel, damping, like: Unknowns, config: SolverConfig, secant: Float[Array, "n n"]
          ) -> tuple[Unknowns, Bool[Array, ""]]:
    """The damped step ``-(H + damping diag(H))^-1 g`` and whether it used ``H + secant`` (dense ``H`` only: where
    that is positive definite)."""
    if model.dense is not None:
        diagonal = jnp.diag(model.dense)
        damped = model.dense + jnp.diag(damping * jnp.maximum(diagonal, DIAGONAL_FLOOR * diagonal.max()))
        # whether H + S is positive definite, then the factor of the matrix chosen (not of both under a `where`:
        # the failed one's NaNs would reach the gradient of the steps)
        augmented = damped + secant
        use = jnp.all(jnp.isfinite(jnp.linalg.cholesky(jax.lax.stop_gradient(augmented))))
        factor = jnp.linalg.cholesky(jnp.where(use, augmented, damped))
        flat = -jax.scipy.linalg.cho_solve((factor, True), _flat(model.gradient, config))
        return _unflat(flat, like, config), use
    shift = jax.tree.map(lambda d: damping * d + CG_RIDGE * (1.0 + d), model.diagonal)
    structure = jax.eval_shape(lambda: like)
    psd = lx.positive_semidefinite_tag
    operator = lx.FunctionLinearOperator(
        lambda v: jax.tree.map(lambda hv, s, vi: hv + s * vi, model.hessian(v), shift, v), structure, psd)
    preconditioner = lx.FunctionLinearOperator(model.blocks.damped_inverse(shift).mv, structure, psd)
    solver = lx.CG(rtol=0.0, atol=0.0, max_steps=config.cg_iterations, stabilise_every=None)
    return lx.linear_solve(operator, jax.tree.map(jnp.negative, model.gradient), solver,
                           options=dict(preconditioner=preconditioner), throw=False).value, jnp.array(False)


def updated_secant(secant: Float[Array, "n n"], step: Float[Array, "n"], gradient_change: Float[Array, "n"],
                   gauss_newton_change: Float[Array, "n"]) -> Float[Array, "n n"]:
    """Dennis, Gay and Welsch's update (NL2SOL) of ``S``, the estimate of the residuals' own curvature
    ``sum_i r_i d2r_i`` that the Gauss-Newton matrix leaves out, after a step ``s``: sized down by
    ``min(1, |s^T y#| / |s^T S s|)``, then the symmetric rank-two change closest to it with ``(H_GN + S) s = y``
    (``y`` the gradient's change, ``y# = y - H_GN s`` the part ``S`` must explain). Unchanged where ``s^T y`` is
    not positive beyond its rounding (the dtype's epsilon times ``|s| |y|``)."""
    s, y = step, gradient_change
    sy = s @ y
    ok = sy > jnp.finfo(sy.dtype).eps * jnp.sqrt((s @ s) * (y @ y))
    ssecs = s @ (secant @ s)
    size = jnp.minimum(1.0, jnp.abs(s @ (y - gauss_newton_change)) / jnp.where(ssecs != 0, jnp.abs(ssecs), 1.0))
    sized = jnp.where(ssecs != 0, size, 1.0) * secant
    w = y - gauss_newton_change - sized @ s
    sy = jnp.where(ok, sy, 1.0)
    new = sized + (jnp.outer(w, y) + jnp.outer(y, w)) / sy - (w @ s) * jnp.outer(y, y) / sy**2
    return jnp.where(ok, 0.5 * (new + new.T), secant)


def retract(y: Unknowns, delta: Unknowns) -> Unknowns:
    """``y`` moved by a step: each rotation by its local increment, ``R_j <- exp(dphi_j) R_j`` (the axis-angle of
    the product nearest ``y``'s, of those that differ by whole turns), shape and camera by addition. The rotations
    compose exactly: a joint turned one way and its child the other stay aligned however large the step."""
    theta = y.pose_rotvecs
    phi = rotations.quat_to_rotvec(rotations.quat_product(rotations.rotvec_to_quat(delta.pose_rotvecs),
                                                         rotations.rotvec_to_quat(theta)))
    norm2 = jnp.sum(phi * phi, -1, keepdims=True)
    turn = 2 * jnp.pi * phi / jnp.sqrt(jnp.where(norm2 > 0, norm2, 1.0))
    candidates = jnp.stack([phi, phi - turn, phi + turn])
    nearest = jnp.argmin(jnp.sum((candidates - theta) ** 2, -1), 0)
    pose = jnp.take_along_axis(candidates, nearest[None, :, None], 0)[0]
    return Unknowns(pose, y.betas + delta.betas, y.camera + delta.camera)


def cost_of(r) -> Float[Array, ""]:
    """Half the sum of squares of every leaf of the residuals ``r``."""
    return 0.5 * sum(jnp.sum(leaf * leaf) for leaf in jax.tree.leaves(r))


class _State(NamedTuple):
    cost: Float[Array, ""]  # at the current point
    damping: Float[Array, ""]  # Marquardt's mu
    growth: Float[Array, ""]  # Nielsen's factor for mu after a rejected step
    converged: Bool[Array, ""]
    secant: Float[Array, "n n"]  # `updated_secant`'s S (dense steps; n = 0 for "cg")
    last_step: Float[Array, "n"]  # the step that led here, when it was taken (``stepped``)
    last_gradient: Float[Array, "n"]  # the gradient where it started
    stepped: Bool[Array, ""]  # whether the last step was taken (the pair then updates S)
    stiff: Bool[Array, "L"]  # bending limits a refused step crossed, while within BEND_MARGIN inside and pressed
    restarted: Bool[Array, ""]  # whether it has stalled once and started again (`stalled`)
    steps: Int[Array, ""]  # steps taken since the solve began (resumed solves go on counting)


class LevenbergMarquardt(optx.AbstractLeastSquaresSolver):
    """Levenberg-Marquardt for `least_squares`' problems, through `optimistix.least_squares`: ``fn`` is `residuals`
    (a step is judged by the cost of ``fn``), ``args`` the `Problem`, whose analytic model (`local_model`) gives
    each step; dense steps on ``H + S`` with ``S`` the residuals' curvature estimated from the steps taken
    (`updated_secant`; halved after a step it mispredicted, left out where ``H + S`` is not positive definite);
    converged when a step at damping at most 1 predicts a relative decrease of the cost of at most ``rtol``.

    ``options``: ``"resume"``, a state a solve of the same problem stopped in (`solve`'s ``resume``), to go on
    from instead of starting afresh; ``"until"``, the step count (since the solve began) at which it pauses.
    ``tags`` are not used: the problem's structure is the model's own."""

    config: SolverConfig = eqx.field(static=True)
    rtol: float
    atol: float = 0.0  # unused: the test is relative
    norm: Callable = optx.max_norm  # unused

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        if options.get("resume") is not None:
            return options["resume"]
        cost = cost_of(fn(y, args)[0])
        one = jnp.ones((), cost.dtype)
        n = _flat(y, self.config).shape[0] if self.config.linear_solver == "cholesky" else 0
        zero = jnp.zeros(n, cost.dtype)
        no = jnp.array(False)
        return _State(cost, self.config.initial_damping * one, 2.0 * one, no, jnp.zeros((n, n), cost.dtype), zero,
                      zero, no, jnp.zeros(len(BEND_LIMITS), bool), no, jnp.zeros((), jnp.int32))

    def step(self, fn, y, args, options, state, tags):
        model = local_model(y, args, self.config, state.stiff)
        secant = state.secant
        if model.dense is not None:
            gradient = _flat(model.gradient, self.config)
            secant = jnp.where(state.stepped, updated_secant(secant, state.last_step, gradient - state.last_gradient,
                                                             model.dense @ state.last_step), secant)
        delta, augmented = _step(model, state.damping, y, self.config, secant)
        predicted = -(_dot(model.gradient, delta) + 0.5 * _dot(delta, model.hessian(delta)))
        if model.dense is not None:
            flat = _flat(delta, self.config)
            predicted = predicted - 0.5 * jnp.where(augmented, flat @ (secant @ flat), 0.0)
        trial = retract(y, delta)
        cost = cost_of(fn(trial, args)[0])
        accept = jnp.isfinite(cost) & (cost < state.cost) & (predicted > 0)
        ratio = (state.cost - cost) / predicted
        converged = (predicted <= self.rtol * state.cost) & (state.damping <= 1.0)
        damping, growth = nielsen_damping(state.damping, state.growth, accept, ratio)
        if model.dense is not None:
            secant = jnp.where(~accept & augmented & (ratio < 0.25), 0.5 * secant, secant)
            last_step = jnp.where(accept, flat, state.last_step)
            last_gradient = jnp.where(accept, gradient, state.last_gradient)
            before, after = bend_of(pose_and_shape(y, args)[0]), bend_of(pose_and_shape(trial, args)[0])
            stiff = jnp.where(accept, state.stiff & (after > -BEND_MARGIN) & (after >= before),
                              state.stiff | ((before <= 0) & (after > 0)))
        else:  # the pipeline's few CG steps hold no limit's stiffness
            last_step, last_gradient, stiff = state.last_step, state.last_gradient, state.stiff
        restart = (damping >= MAX_DAMPING) & ~state.restarted
        new = _State(jnp.where(accept, cost, state.cost), jnp.where(restart, 1.0, damping),
                     jnp.where(restart, 2.0, growth), converged,
                     jnp.where(restart, 0.0, secant), last_step, last_gradient, accept, stiff,
                     state.restarted | restart, state.steps + 1)
        return jax.tree.map(lambda a, b: jnp.where(accept, a, b), trial, y), new, None

    def terminate(self, fn, y, args, options, state, tags):
        until = options.get("until")
        stop = finished(state) | (False if until is None else state.steps >= until)
        return stop, optx.RESULTS.where(stop & ~state.converged, optx.RESULTS.nonlinear_max_steps_reached,
                                        optx.RESULTS.successful)

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        return y, aux, {}


def stalled(state: _State) -> Bool[Array | np.ndarray, "*frames"]:
    """Whether refused steps have raised the damping to `MAX_DAMPING` a second time. The first time, the solve
    starts again at damping 1 without ``S``: each refused step halves ``S`` but multiplies the damping by a growing
    factor, so by the time ``S`` no longer misleads, the damping has run past every step that would lower the cost
    (docs/BENCHMARKS.md, "Optimization integration"). The
    second time, no step however short lowers the cost (its steps are some 1e-10 of a gradient step, below the
    cost's resolution in float32), and the solve stops, not converged, as at its step cap."""
    return state.damping >= MAX_DAMPING


def finished(state: _State) -> Bool[Array | np.ndarray, "*frames"]:
    """Whether the solve stops here, short of its step cap: converged or `stalled`."""
    return state.converged | stalled(state)


def default_tolerance(dtype) -> float:
    """`SolverConfig.tolerance` where None: a predicted relative decrease of 1e-5 in float32 (what its rounding
    of the cost still resolves), 1e-10 in float64."""
    return 1e-10 if jnp.dtype(dtype) == jnp.float64 else 1e-5


def _solver(config: SolverConfig, dtype) -> LevenbergMarquardt:
    return LevenbergMarquardt(config, config.tolerance or default_tolerance(dtype))


def initial_state(problem: Problem, y0: Unknowns, config: SolverConfig) -> _State:
    """The state a solve of ``problem`` starts in at ``y0`` (`solve`'s ``resume``, for a solve run in pieces)."""
    def fn(y, args):  # as `optimistix.least_squares` gives it to the solver: no aux
        return residuals(y, args, config), None

    return _solver(config, y0.camera.dtype).init(fn, y0, problem, {}, None, None, frozenset())


def solve(problem: Problem, y0: Unknowns, config: SolverConfig, adjoint: optx.AbstractAdjoint | None = None,
          resume: _State | None = None, until: Int[Array, ""] | None = None) -> optx.Solution:
    """Minimise the cost of `residuals` from ``y0`` by `optimistix.least_squares` (`LevenbergMarquardt`, at most
    ``config.iterations`` steps; ``result`` successful when converged, ``nonlinear_max_steps_reached`` otherwise; no
    exception under `jax.vmap`). ``adjoint``: how gradients go through the solve (default
    `optimistix.ImplicitAdjoint`). In pieces: ``resume`` a state from `initial_state` or a previous piece's
    ``Solution.state`` (with that piece's value as ``y0``), ``until`` the step count at which this piece pauses
    (`finished` says whether the solve is done); the pieces take the steps one solve would."""
    options = {"resume": resume, "until": until}
    return optx.least_squares(jax.tree_util.Partial(residuals, config=config), _solver(config, y0.camera.dtype),
                              y0, problem, options=options, max_steps=config.iterations, throw=False,
                              adjoint=optx.ImplicitAdjoint() if adjoint is None else adjoint)
