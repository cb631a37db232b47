"""Symmetric positive definite block-banded systems of a time series: ``T`` blocks of ``m`` unknowns, ``A[t, s] = 0``
for ``|t - s| > 2``, factored and solved exactly, frame by frame (work linear in ``T``; a dense factor costs
``T^3``).

``A`` is held by its lower blocks (`Banded`): ``diagonal[t] = A[t, t]``, ``first[t] = A[t + 1, t]``,
``second[t] = A[t + 2, t]`` (rows past the end are ignored). Each frame's step factors one ``m x m`` block of each
system, never a batch of them: jaxlib's batched LAPACK kernels run on XLA's thread pool, and two at once on a
two-core machine wait on each other for ever. A matrix that is not positive definite gives non-finite values
(a solver's step is then refused), never an exception.
"""

from __future__ import annotations

from collections.abc import Sequence
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


def factor(systems: Sequence[Banded]) -> tuple[Factor, ...]:
    """The block Cholesky factor of each of ``systems`` (each its own ``m``; one pass over the frames for all),
    frame by frame: ``L[t, t-2] = A[t, t-2] L[t-2, t-2]^-T``, ``L[t, t-1] = (A[t, t-1] - L[t, t-2] L[t-1, t-2]^T)
    L[t-1, t-1]^-T`` (products with the inverses already found), ``L[t, t]`` the Cholesky factor of ``A[t, t] -
    L[t, t-1] L[t, t-1]^T - L[t, t-2] L[t, t-2]^T``."""
    eyes = [jnp.eye(a.diagonal.shape[1], dtype=a.diagonal.dtype) for a in systems]

    def row(carry, blocks):
        out, new = [], []
        for (inverse1, before_first, inverse2), (diagonal, first, second), eye in zip(carry, blocks, eyes):
            # inverse1 = L[t-1, t-1]^-1, before_first = L[t-1, t-2], inverse2 = L[t-2, t-2]^-1
            l2 = second @ inverse2.T
            l1 = (first - l2 @ before_first.T) @ inverse1.T
            inverse = solve_triangular(jnp.linalg.cholesky(diagonal - l1 @ l1.T - l2 @ l2.T), eye, lower=True)
            new.append((inverse, l1, inverse1))
            out.append((l1, l2, inverse))
        return new, out

    start = [(eye, jnp.zeros_like(eye), eye) for eye in eyes]
    _, blocks = jax.lax.scan(row, start, [(a.diagonal, _shifted(a.first, 1), _shifted(a.second, 2))
                                          for a in systems])
    return tuple(Factor(*b) for b in blocks)


def solve(factors: Sequence[Factor], gs: Sequence[Float[Array, "T _"]]) -> tuple[Float[Array, "T _"], ...]:
    """``A^-1 g`` of each system from its factor (`factor`): ``L z = g`` forwards, then ``L^T x = z`` backwards,
    one pass each way for all."""
    zeros = [(jnp.zeros_like(g[0]), jnp.zeros_like(g[0])) for g in gs]

    def forward(carry, blocks):
        new = [(f.inverse @ (gt - f.first @ z1 - f.second @ z2), z1)
               for (z1, z2), (f, gt) in zip(carry, blocks)]  # z[t], z[t-1]
        return new, [z for z, _ in new]

    _, zs = jax.lax.scan(forward, zeros, [(f, g) for f, g in zip(factors, gs)])
    up = [(jnp.concatenate([f.first[1:], jnp.zeros_like(f.first[:1])]),  # L[t+1, t]
           jnp.concatenate([f.second[2:], jnp.zeros_like(f.second[:2])]), f.inverse) for f in factors]  # L[t+2, t]

    def backward(carry, blocks):
        new = [(inverse.T @ (zt - u1.T @ x1 - u2.T @ x2), x1)
               for (x1, x2), ((u1, u2, inverse), zt) in zip(carry, blocks)]  # x[t], x[t+1]
        return new, [x for x, _ in new]

    _, xs = jax.lax.scan(backward, zeros, [(u, z) for u, z in zip(up, zs)], reverse=True)
    return tuple(xs)
