"""3-vectors and 3x3 matrices stored coordinate-major, ``(3, N)`` and ``(3, 3, N)``, one per column, with the
products written out by component: XLA fuses them into a few loops, where a batch of tiny dots is slow on CPU,
and under `jax.vmap` the column axis stays last, so products with constant ``(N, M)`` matrices are single GEMMs."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from smplx_jax.rotations import skew_polynomial


def cross(a: Float[Array, "3 *N"], b: Float[Array, "3 *N"]) -> Float[Array, "3 *N"]:
    """Cross products of 3-vectors stored coordinate-major (the first axis)."""
    return jnp.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def matvec(m: Float[Array, "3 3 ... N"], v: Float[Array, "3 ... N"]) -> Float[Array, "3 ... N"]:
    """``m @ v`` per column (``m`` and ``v`` may hold several per column, broadcast: ``(3, 3, B, N)``,
    ``(3, B, N)``)."""
    return jnp.stack([m[i, 0] * v[0] + m[i, 1] * v[1] + m[i, 2] * v[2] for i in range(3)])


def matvec_t(m: Float[Array, "3 3 N"], v: Float[Array, "3 N"]) -> Float[Array, "3 N"]:
    """``m^T @ v`` per column."""
    return jnp.stack([m[0, i] * v[0] + m[1, i] * v[1] + m[2, i] * v[2] for i in range(3)])


def matmul(a: Float[Array, "3 3 N"], b: Float[Array, "3 3 N"]) -> Float[Array, "3 3 N"]:
    """Products of 3x3 matrices stored with the batch last, ``(3, 3, N)``, written out (no batched GEMM)."""
    return jnp.stack([jnp.stack([a[i, 0] * b[0, k] + a[i, 1] * b[1, k] + a[i, 2] * b[2, k] for k in range(3)])
                      for i in range(3)])


def inverse(m: Float[Array, "3 3 N"]) -> Float[Array, "3 3 N"]:
    """Inverse per column, by cofactors."""
    a, b, c = m[0, 0], m[0, 1], m[0, 2]
    d, e, f = m[1, 0], m[1, 1], m[1, 2]
    g, h, i = m[2, 0], m[2, 1], m[2, 2]
    cof = jnp.stack([jnp.stack([e * i - f * h, c * h - b * i, b * f - c * e]),
                     jnp.stack([f * g - d * i, a * i - c * g, c * d - a * f]),
                     jnp.stack([d * h - e * g, b * g - a * h, a * e - b * d])])
    return cof / (a * cof[0, 0] + b * cof[1, 0] + c * cof[2, 0])


def left_jacobian(rotvec: Float[Array, "... 3"]) -> Float[Array, "... 3 3"]:
    """SO(3)'s left Jacobian ``I + (1 - cos t)/t^2 K + (t - sin t)/t^3 K^2``, ``K = skew(rotvec)`` (series near
    zero): a rotation ``exp(rotvec + d)`` is ``exp(left_jacobian(rotvec) d) exp(rotvec)`` to first order."""
    t2 = jnp.sum(rotvec * rotvec, axis=-1)
    small = t2 < 1e-2  # below, the series is exact to float64 rounding; above, float32 cancels little
    t2s = jnp.where(small, 1.0, t2)
    t = jnp.sqrt(t2s)
    c1 = jnp.where(small, 1 / 2 - t2 / 24 + t2**2 / 720 - t2**3 / 40320, (1.0 - jnp.cos(t)) / t2s)
    c2 = jnp.where(small, 1 / 6 - t2 / 120 + t2**2 / 5040 - t2**3 / 362880, (t - jnp.sin(t)) / (t2s * t))
    return skew_polynomial(rotvec, c1, c2)
