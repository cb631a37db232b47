"""The solver of `clip`: Levenberg-Marquardt on a time series, matrix-free.

An `optimistix.AbstractLeastSquaresSolver` for unknowns ``(pose_rotvecs (T, J, 3), transl (T, 3), betas (B,))``
(`clip.ClipUnknowns`). Each step linearises ``fn`` itself (`jax.linearize`, and its transpose), or, where
``options["reweighted"](y, args, weighed_at=y0)`` is given, those residuals with their robust weights held at the
step's start (iteratively reweighted least squares: the same gradient, and a Gauss-Newton matrix that models a
robust cost far better); so the gradient ``J^T r`` is exact and ``J^T J v`` costs one forward and one backward
pass over the clip, whatever couples the frames. The damped Gauss-Newton system ``(J^T J + mu D) d = -J^T r`` is
solved by conjugate gradients, preconditioned by blocks of ``J^T J`` that ``options["preconditioner"](y, args)``
gives at each step (`Preconditioner`; `clip.preconditioner`), ``D`` their diagonal; steps are judged by ``fn``'s
cost. Work and memory are linear in the number of frames.

Rotations move by local increments, ``R <- exp(dphi) R`` (`levenberg_marquardt.retract`), translations and the
shape by addition. ``mu`` follows Nielsen's rule; the solve has converged when, at damping at most 1, half the
Newton decrement with the preconditioner's blocks for ``J^T J`` (``g^T P^-1 g / 2``, the decrease the model
predicts were it at the optimum in one step) falls below ``tolerance`` (in the cost's units), and stops
unconverged when refused steps raise the damping to `MAX_DAMPING`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple, Protocol

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx
from jaxtyping import Array, Bool, Float

from jaxmocap.integrate.least_squares import Unknowns
from jaxmocap.integrate.levenberg_marquardt import MAX_DAMPING, cost_of, nielsen_damping, retract

# The smallest entry of each part's diagonal (rotations, translations, shape) the damping scales by, relative to
# that part's largest: an unknown no term constrains still gets a positive damping.
DIAGONAL_FLOOR = 1e-9


class Step(NamedTuple):
    """A step, or any vector of the unknowns' tangent space: rotation increments, translations, shape."""

    pose: Float[Array, "T J 3"]
    transl: Float[Array, "T 3"]
    betas: Float[Array, "B"]


class Preconditioner(Protocol):
    """Blocks of ``J^T J`` along its diagonal, positive definite: what the conjugate gradients are preconditioned by
    and the damping scales."""

    def diagonal(self) -> Step:
        """The diagonal of the blocks."""

    def damped_inverse(self, shift: Step) -> Callable[[Step], Step]:
        """``v -> (blocks + diag(shift))^-1 v``."""


def _dot(a: Step, b: Step):
    return sum(jnp.sum(x * y) for x, y in zip(a, b))


def moved(y, step: Step, fit_shared: bool):
    """``y`` moved by ``step``: each rotation by its local increment, translations and the shape by addition."""
    none = step.betas[:0]
    pose = jax.vmap(lambda p, d: retract(Unknowns(p, none, none), Unknowns(d, none, none)).pose_rotvecs)(
        y.pose_rotvecs, step.pose)
    return y._replace(pose_rotvecs=pose, transl=y.transl + step.transl,
                      betas=y.betas + step.betas if fit_shared else y.betas)


class _State(NamedTuple):
    cost: Float[Array, ""]
    damping: Float[Array, ""]
    growth: Float[Array, ""]
    converged: Bool[Array, ""]


class ClipLevenbergMarquardt(optx.AbstractLeastSquaresSolver):
    """Matrix-free Levenberg-Marquardt (module docstring). ``fit_shared``: whether the shape is solved for (else it
    keeps its value); ``tolerance``: the predicted decrease of the cost below which it has converged;
    ``cg_iterations``: the conjugate-gradient steps of each step's system."""

    tolerance: Float[Array, ""]
    fit_shared: bool = eqx.field(static=True, default=True)
    cg_iterations: int = eqx.field(static=True, default=10)
    rtol: float = 0.0  # unused: the test is `tolerance`
    atol: float = 0.0  # unused
    norm: Callable = optx.max_norm  # unused
    initial_damping: float = 1e-2

    def init(self, fn, y, args, options, f_struct, aux_struct, tags):
        cost = cost_of(fn(y, args)[0])
        one = jnp.ones((), cost.dtype)
        return _State(cost, self.initial_damping * one, 2.0 * one, jnp.array(False))

    def _zero(self, y) -> Step:
        return Step(jnp.zeros_like(y.pose_rotvecs), jnp.zeros_like(y.transl),
                    jnp.zeros_like(y.betas) * (1.0 if self.fit_shared else 0.0))

    def step(self, fn, y, args, options, state, tags):
        zero = self._zero(y)
        reweighted = options.get("reweighted")
        residual = (lambda s: fn(moved(y, s, self.fit_shared), args)[0]) if reweighted is None else (
            lambda s: reweighted(moved(y, s, self.fit_shared), args, weighed_at=y))
        r, linear = jax.linearize(residual, zero)
        transpose = jax.linear_transpose(linear, zero)

        def keep_shape(v: Step) -> Step:
            return v if self.fit_shared else v._replace(betas=jnp.zeros_like(v.betas))

        gradient = keep_shape(transpose(r)[0])
        blocks = options["preconditioner"](y, args)
        diagonal = blocks.diagonal()
        floor = jax.tree.map(lambda d: DIAGONAL_FLOOR * jnp.max(d) + jnp.finfo(d.dtype).tiny, diagonal)
        shift = jax.tree.map(lambda d, f: state.damping * jnp.maximum(d, f), diagonal, floor)
        if not self.fit_shared:
            shift = shift._replace(betas=jnp.ones_like(shift.betas))

        def hessian(v: Step) -> Step:
            return keep_shape(transpose(linear(v))[0])

        structure = jax.eval_shape(lambda: zero)
        operator = lx.FunctionLinearOperator(
            lambda v: jax.tree.map(lambda hv, s, vi: hv + s * vi, hessian(v), shift, v), structure,
            lx.positive_semidefinite_tag)
        inverse = blocks.damped_inverse(shift)
        preconditioner = lx.FunctionLinearOperator(inverse, structure, lx.positive_semidefinite_tag)
        solver = lx.CG(rtol=0.0, atol=0.0, max_steps=self.cg_iterations, stabilise_every=None)
        delta = lx.linear_solve(operator, jax.tree.map(jnp.negative, gradient), solver,
                                options=dict(preconditioner=preconditioner), throw=False).value
        predicted = -(_dot(gradient, delta) + 0.5 * _dot(delta, hessian(delta)))
        trial = moved(y, delta, self.fit_shared)
        cost = cost_of(fn(trial, args)[0])
        accept = jnp.isfinite(cost) & (cost < state.cost) & (predicted > 0)
        ratio = (state.cost - cost) / predicted
        # the decrease a step would predict were the blocks the whole Gauss-Newton matrix (half the Newton
        # decrement): unlike the step's own, it does not shrink when the conjugate gradients fall short
        decrement = 0.5 * _dot(gradient, inverse(gradient))
        converged = (decrement <= self.tolerance) & (state.damping <= 1.0)
        damping, growth = nielsen_damping(state.damping, state.growth, accept, ratio)
        new = _State(jnp.where(accept, cost, state.cost), damping, growth, converged)
        return jax.tree.map(lambda a, b: jnp.where(accept, a, b), trial, y), new, None

    def terminate(self, fn, y, args, options, state, tags):
        stop = state.converged | (state.damping >= MAX_DAMPING)
        return stop, optx.RESULTS.where(stop & ~state.converged, optx.RESULTS.nonlinear_max_steps_reached,
                                        optx.RESULTS.successful)

    def postprocess(self, fn, y, aux, args, options, state, tags, result):
        return y, aux, {}
