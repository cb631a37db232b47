"""Levenberg-Marquardt parts for optimistix that never form a Jacobian: `DampedNewtonCG` and `DampingSearch`.

The descent asks the problem for a local quadratic model at the last accepted point ``y``: ``model(y)`` returns
the cost's gradient ``g``, the product ``v -> H v`` with a positive semi-definite ``H`` (Gauss-Newton's
``J^T J``, or for a robust cost the IRLS Hessian, a majorising model whose unit step does not overshoot) and a
block diagonal of ``H`` (an object with ``diagonal()`` and ``damped_inverse(shift)``, whose ``mv(v)`` applies
it). Each step solves ``(H + mu D) delta = -g``, ``D`` Marquardt's scaling (the diagonal of ``H``), by a fixed
number of conjugate-gradient iterations (`lineax.CG`) preconditioned by the inverse of the damped block diagonal.
``mu = damping / step_size``: the search steers the damping through the step size.

Everything the step needs is computed in `DampedNewtonCG.step` from ``y`` alone: under `jax.vmap` optimistix
accepts or rejects inside a `lax.cond` on a batched predicate, which broadcasts every operand to the batch, so
the problem's constants must stay out of it (`query` only keeps ``y``).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import lineax as lx
import optimistix as optx


class _DescentState(eqx.Module):
    y: Any  # the last accepted point


class DampedNewtonCG(optx.AbstractDescent):
    """Marquardt-scaled damped Newton step on a local model, by preconditioned CG (see the module docstring)."""

    model: Callable[[Any], tuple[Any, Callable[[Any], Any], Any]]  # y -> (gradient, v -> H v, blocks of H)
    damping: float
    cg_steps: int

    def init(self, y, f_info_struct):
        del f_info_struct
        return _DescentState(y)

    def query(self, y, f_info, state):
        del f_info, state
        return _DescentState(y)

    def step(self, step_size, state):
        gradient, hessian, blocks = self.model(state.y)
        mu = self.damping / jnp.maximum(step_size, jnp.finfo(step_size.dtype).tiny)
        shift = jax.tree.map(lambda d: mu * d + 1e-9 * (1.0 + d), blocks.diagonal())
        structure = jax.eval_shape(lambda: state.y)
        psd = lx.positive_semidefinite_tag
        operator = lx.FunctionLinearOperator(
            lambda v: jax.tree.map(lambda hv, s, vi: hv + s * vi, hessian(v), shift, v), structure, psd)
        preconditioner = lx.FunctionLinearOperator(blocks.damped_inverse(shift).mv, structure, psd)
        cg = lx.CG(rtol=0.0, atol=0.0, max_steps=self.cg_steps, stabilise_every=None)
        delta = lx.linear_solve(operator, jax.tree.map(jnp.negative, gradient), cg,
                                options=dict(preconditioner=preconditioner), throw=False).value
        finite = jnp.all(jnp.stack([jnp.all(jnp.isfinite(d)) for d in jax.tree.leaves(delta)]))
        return jax.tree.map(lambda d: jnp.where(finite, d, 0.0), delta), optx.RESULTS.successful


class _SearchState(eqx.Module):
    step_size: Any


class DampingSearch(optx.AbstractSearch):
    """Marquardt's damping rule through the step size: accept a step when the cost falls and grow the step
    size (less damping) by ``grow``, else shrink it by ``shrink``. Needs only the cost: optimistix's own
    linearisation of the residuals goes unused and XLA drops it."""

    grow: float = 1.5
    shrink: float = 0.1

    def init(self, y, f_info_struct):
        del f_info_struct
        return _SearchState(jnp.ones((), jax.tree.leaves(y)[0].dtype))

    def step(self, first_step, y, y_eval, f_info, f_eval_info, state):
        del y, y_eval
        accept = first_step | (f_eval_info.as_min() < f_info.as_min())
        step_size = state.step_size * jnp.where(first_step, 1.0, jnp.where(accept, self.grow, self.shrink))
        return step_size, accept, optx.RESULTS.successful, _SearchState(step_size)
