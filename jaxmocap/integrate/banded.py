"""Symmetric positive definite block-banded systems of a time series: ``T`` blocks of ``m`` unknowns, ``A[t, s] = 0``
for ``|t - s| > 2``, factored and solved exactly, frame by frame (work linear in ``T``; a dense factor costs
``T^3``).

``A`` is held by its lower blocks (`Banded`): ``diagonal[t] = A[t, t]``, ``first[t] = A[t + 1, t]``,
``second[t] = A[t + 2, t]`` (rows past the end are ignored). Each frame's step factors one ``m x m`` block,
never a batch of them: jaxlib's batched LAPACK kernels run on XLA's thread pool, and two at once on a
two-core machine wait on each other for ever. A matrix that is not positive definite gives non-finite values
(a solver's step is then refused), never an exception.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
from jax.scipy.linalg import solve_triangular
from jaxtyping import Array, Float


class Banded(NamedTuple):
    """The lower blocks of a symmetric block-banded matrix of ``T`` frames, ``m`` unknowns each, bandwidth 2."""

    diagonal: Float[Array, "T m m"]  # A[t, t]
    first: Float[Array, "T m m"]  # A[t + 1, t]; the last is ignored
    second: Float[Array, "T m m"]  # A[t + 2, t]; the last two are ignored

    def dense(self) -> Float[Array, "Tm Tm"]:
        """``A`` as one dense matrix (for tests and small problems)."""
        t, m, _ = self.diagonal.shape
        full = jnp.zeros((t, m, t, m), self.diagonal.dtype)
        for i in range(t):
            full = full.at[i, :, i, :].set(self.diagonal[i])
            for offset, blocks in ((1, self.first), (2, self.second)):
                if i + offset < t:
                    full = full.at[i + offset, :, i, :].set(blocks[i]).at[i, :, i + offset, :].set(blocks[i].T)
        return full.reshape(t * m, t * m)


class Factor(NamedTuple):
    """`factor`'s result: ``L`` lower triangular by blocks, ``L L^T = A``, held by its blocks below the diagonal
    and the inverses of its diagonal blocks (so that `solve` multiplies, where triangular solves would each be a
    LAPACK call)."""

    first: Float[Array, "T m m"]  # L[t, t - 1] (zero at t = 0)
    second: Float[Array, "T m m"]  # L[t, t - 2] (zero at t < 2)
    inverse: Float[Array, "T m m"]  # L[t, t]^-1


def _shifted(blocks, by: int):
    """``blocks[t - by]`` at ``t``, zeros before."""
    return jnp.concatenate([jnp.zeros_like(blocks[:by]), blocks[:blocks.shape[0] - by]])


def _right_solve_t(lower, b):
    """``b lower^-T`` for a lower triangular ``lower``."""
    return solve_triangular(lower, b.T, lower=True).T


def factor(a: Banded) -> Factor:
    """The block Cholesky factor of ``a``, frame by frame: ``L[t, t-2] = A[t, t-2] L[t-2, t-2]^-T``,
    ``L[t, t-1] = (A[t, t-1] - L[t, t-2] L[t-1, t-2]^T) L[t-1, t-1]^-T``, ``L[t, t]`` the Cholesky factor of
    ``A[t, t] - L[t, t-1] L[t, t-1]^T - L[t, t-2] L[t, t-2]^T``."""
    eye = jnp.eye(a.diagonal.shape[1], dtype=a.diagonal.dtype)

    def row(carry, blocks):
        before, before_first, before2 = carry  # L[t-1, t-1], L[t-1, t-2], L[t-2, t-2]
        diagonal, first, second = blocks  # A[t, t], A[t, t-1], A[t, t-2]
        l2 = _right_solve_t(before2, second)
        l1 = _right_solve_t(before, first - l2 @ before_first.T)
        l0 = jnp.linalg.cholesky(diagonal - l1 @ l1.T - l2 @ l2.T)
        return (l0, l1, before), (l1, l2, solve_triangular(l0, eye, lower=True))

    _, blocks = jax.lax.scan(row, (eye, jnp.zeros_like(eye), eye),
                             (a.diagonal, _shifted(a.first, 1), _shifted(a.second, 2)))
    return Factor(*blocks)


def solve(f: Factor, g: Float[Array, "T m"]) -> Float[Array, "T m"]:
    """``A^-1 g`` from ``A``'s factor: ``L z = g`` forwards, then ``L^T x = z`` backwards."""
    zero = jnp.zeros_like(g[0])

    def forward(carry, blocks):
        z1, z2 = carry  # z[t-1], z[t-2]
        l1, l2, inverse, gt = blocks
        z = inverse @ (gt - l1 @ z1 - l2 @ z2)
        return (z, z1), z

    _, z = jax.lax.scan(forward, (zero, zero), (f.first, f.second, f.inverse, g))
    up1 = jnp.concatenate([f.first[1:], jnp.zeros_like(f.first[:1])])  # L[t+1, t]
    up2 = jnp.concatenate([f.second[2:], jnp.zeros_like(f.second[:2])])  # L[t+2, t]

    def backward(carry, blocks):
        x1, x2 = carry  # x[t+1], x[t+2]
        u1, u2, inverse, zt = blocks
        x = inverse.T @ (zt - u1.T @ x1 - u2.T @ x2)
        return (x, x1), x

    _, x = jax.lax.scan(backward, (zero, zero), (up1, up2, f.inverse, z), reverse=True)
    return x
