"""Rotation conversions: axis-angle (rotvec), rotation matrix, unit quaternion (w, x, y, z) and 6D.

All functions take arrays with any leading batch shape. Near the identity they switch to Taylor series
with the ``where``-twice pattern, so values and gradients are exact and finite at zero rotation without
adding an epsilon to the input. They are jitted: called outside any jit, one compiled program runs per shape (not
each of its ~30 operations compiled and run alone); inside a trace they join the caller's program.
"""

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

_SMALL = 1e-6  # squared angle (or squared sine) below which the series are exact to float64 rounding


def skew_polynomial(rotvec: Float[Array, "... 3"], a: Float[Array, "..."], b: Float[Array, "..."]):
    """``I + a K + b K^2`` with ``K = skew(rotvec)``, written out entry by entry with ``K^2 = v v^T - |v|^2 I``
    (XLA fuses it into a few loops; a batch of tiny matrix products is far slower on CPU)."""
    x, y, z = rotvec[..., 0], rotvec[..., 1], rotvec[..., 2]
    diagonal = 1.0 - b * (x * x + y * y + z * z)
    ax, ay, az = a * x, a * y, a * z
    bx, by, bz = b * x, b * y, b * z
    entries = [diagonal + bx * x, bx * y - az, bx * z + ay,
               bx * y + az, diagonal + by * y, by * z - ax,
               bx * z - ay, by * z + ax, diagonal + bz * z]
    return jnp.stack(entries, axis=-1).reshape(rotvec.shape[:-1] + (3, 3))


@jax.jit
def rotvec_to_rotmat(rotvec: Float[ArrayLike, "... 3"]) -> Float[Array, "... 3 3"]:
    """Rodrigues' formula R = I + sin(t)/t K + (1 - cos t)/t^2 K^2 with K = skew(rotvec), t = |rotvec|."""
    rotvec = jnp.asarray(rotvec)
    theta2 = jnp.sum(rotvec * rotvec, axis=-1)
    small = theta2 < _SMALL
    theta = jnp.sqrt(jnp.where(small, 1.0, theta2))
    sinc = jnp.where(small, 1.0 - theta2 / 6.0 + theta2**2 / 120.0, jnp.sin(theta) / theta)
    cosc = jnp.where(small, 0.5 - theta2 / 24.0 + theta2**2 / 720.0, (1.0 - jnp.cos(theta)) / (theta * theta))
    return skew_polynomial(rotvec, sinc, cosc)


@jax.jit
def rotmat_to_quat(rotmat: Float[ArrayLike, "... 3 3"]) -> Float[Array, "... 4"]:
    """Unit quaternion (w, x, y, z) with w >= 0, from the best-conditioned of the four standard formulas."""
    m = rotmat
    m00, m01, m02 = m[..., 0, 0], m[..., 0, 1], m[..., 0, 2]
    m10, m11, m12 = m[..., 1, 0], m[..., 1, 1], m[..., 1, 2]
    m20, m21, m22 = m[..., 2, 0], m[..., 2, 1], m[..., 2, 2]
    # 4 q_i^2 for i = w, x, y, z; they sum to 4, so the largest is >= 1 and its root is safe.
    sq = jnp.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22], axis=-1)
    candidates = jnp.stack([
        jnp.stack([sq[..., 0], m21 - m12, m02 - m20, m10 - m01], axis=-1),
        jnp.stack([m21 - m12, sq[..., 1], m10 + m01, m02 + m20], axis=-1),
        jnp.stack([m02 - m20, m10 + m01, sq[..., 2], m12 + m21], axis=-1),
        jnp.stack([m10 - m01, m20 + m02, m21 + m12, sq[..., 3]], axis=-1),
    ], axis=-2)
    best = jnp.argmax(sq, axis=-1)
    picked = jnp.take_along_axis(candidates, best[..., None, None], axis=-2)[..., 0, :]
    scale = jnp.take_along_axis(sq, best[..., None], axis=-1)
    quat = picked / (2.0 * jnp.sqrt(scale))
    return jnp.where(quat[..., :1] < 0, -quat, quat)


@jax.jit
def quat_to_rotvec(quat: Float[ArrayLike, "... 4"]) -> Float[Array, "... 3"]:
    """Axis-angle of a unit quaternion (w, x, y, z); angle in [0, pi]."""
    quat = jnp.where(quat[..., :1] < 0, -quat, quat)
    w, v = quat[..., 0], quat[..., 1:]
    sin2 = jnp.sum(v * v, axis=-1)
    small = sin2 < _SMALL
    sin = jnp.sqrt(jnp.where(small, 1.0, sin2))
    # 2 atan2(s, w) / s, and its series 2/w - 2 s^2 / (3 w^3) near s = 0 (where w ~ 1).
    w_safe = jnp.where(small, w, 1.0)
    factor = jnp.where(small, 2.0 / w_safe - 2.0 * sin2 / (3.0 * w_safe**3), 2.0 * jnp.arctan2(sin, w) / sin)
    return factor[..., None] * v


@jax.jit
def quat_to_rotmat(quat: Float[ArrayLike, "... 4"]) -> Float[Array, "... 3 3"]:
    """Rotation matrix of a quaternion (w, x, y, z); the quaternion is normalised first."""
    quat = quat / jnp.linalg.norm(quat, axis=-1, keepdims=True)
    w, x, y, z = quat[..., 0], quat[..., 1], quat[..., 2], quat[..., 3]
    rows = [
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ]
    return jnp.stack(rows, axis=-1).reshape(quat.shape[:-1] + (3, 3))


def quat_product(a: Float[ArrayLike, "... 4"], b: Float[ArrayLike, "... 4"]) -> Float[Array, "... 4"]:
    """Hamilton's product ``a b`` of quaternions (w, x, y, z): the rotation ``b`` then ``a``."""
    wa, va, wb, vb = a[..., :1], a[..., 1:], b[..., :1], b[..., 1:]
    return jnp.concatenate([wa * wb - jnp.sum(va * vb, -1, keepdims=True), wa * vb + wb * va + jnp.cross(va, vb)], -1)


@jax.jit
def rotvec_to_quat(rotvec: Float[ArrayLike, "... 3"]) -> Float[Array, "... 4"]:
    """Unit quaternion (w, x, y, z) of an axis-angle vector."""
    theta2 = jnp.sum(rotvec * rotvec, axis=-1)
    small = theta2 < _SMALL
    theta = jnp.sqrt(jnp.where(small, 1.0, theta2))
    half_sinc = jnp.where(small, 0.5 - theta2 / 48.0, jnp.sin(theta / 2) / theta)
    w = jnp.where(small, 1.0 - theta2 / 8.0, jnp.cos(theta / 2))
    return jnp.concatenate([w[..., None], half_sinc[..., None] * rotvec], axis=-1)


@jax.jit
def rotmat_to_rotvec(rotmat: Float[ArrayLike, "... 3 3"]) -> Float[Array, "... 3"]:
    """Axis-angle of a rotation matrix; angle in [0, pi]."""
    return quat_to_rotvec(rotmat_to_quat(rotmat))


@jax.jit
def rot6d_to_rotmat(rot6d: Float[ArrayLike, "... 6"]) -> Float[Array, "... 3 3"]:
    """The 6D representation (a 3x2 matrix read row by row) to a rotation by Gram-Schmidt of its columns."""
    a = rot6d.reshape(rot6d.shape[:-1] + (3, 2))
    a1, a2 = a[..., 0], a[..., 1]
    b1 = a1 / jnp.linalg.norm(a1, axis=-1, keepdims=True)
    b2 = a2 - jnp.sum(b1 * a2, axis=-1, keepdims=True) * b1
    b2 = b2 / jnp.linalg.norm(b2, axis=-1, keepdims=True)
    b3 = jnp.cross(b1, b2)
    return jnp.stack([b1, b2, b3], axis=-1)


@jax.jit
def rotmat_to_rot6d(rotmat: Float[ArrayLike, "... 3 3"]) -> Float[Array, "... 6"]:
    """The first two columns of a rotation matrix, read row by row (inverse of `rot6d_to_rotmat`)."""
    rotmat = jnp.asarray(rotmat)
    return rotmat[..., :, :2].reshape(rotmat.shape[:-2] + (6,))
