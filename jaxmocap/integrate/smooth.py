"""Temporal smoothing of per-frame fits with FrankMocap's kernel ``[0.1, 0.2, 0.5, 0.2, 0.1]``.

Rotations are averaged as unit quaternions, each neighbour's sign aligned to the centre frame's (q and -q are
one rotation), then normalised: averaging raw axis-angles is wrong near pi, where a rotation's axis-angle jumps
between ``v`` and ``-(2 pi - |v|) v/|v|``. Other parameters are averaged linearly. Frames marked invalid neither
contribute nor change; at the ends and beside invalid frames the kernel is renormalised over what is there.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from jaxmocap.integrate.keypoints import params_of
from smplx_jax import SMPLXParams
from smplx_jax.rotations import quat_to_rotvec, rotvec_to_quat

KERNEL = (0.1, 0.2, 0.5, 0.2, 0.1)


def _shifted(x, offset):
    """``x[t + offset]`` with zeros outside ``[0, T)``."""
    t = x.shape[0]
    pad = jnp.zeros((abs(offset),) + x.shape[1:], x.dtype)
    if offset > 0:
        return jnp.concatenate([x[offset:], pad])[:t]
    if offset < 0:
        return jnp.concatenate([pad, x[:offset]])[:t]
    return x


def _weights(valid, kernel):
    half = len(kernel) // 2
    v = valid.astype(jnp.float32)
    return [(o - half, k * _shifted(v, o - half)) for o, k in enumerate(kernel)]


def _expand(w, like):
    return w.reshape(w.shape + (1,) * (like.ndim - 1))


def smooth_linear(values: Float[Array, "T ..."], valid: Bool[Array, "T"], kernel=KERNEL) -> Float[Array, "T ..."]:
    """``values`` averaged over time with ``kernel``, over the ``valid`` frames only (module docstring);
    invalid frames are returned unchanged."""
    total = 0.0
    acc = jnp.zeros_like(values)
    for offset, w in _weights(valid, kernel):
        acc = acc + _expand(w, values) * _shifted(values, offset)
        total = total + w
    out = acc / _expand(jnp.where(total > 0, total, 1.0), values)
    return jnp.where(_expand(valid, values), out, values)


def smooth_rotvecs(rotvecs: Float[Array, "T ... 3"], valid: Bool[Array, "T"], kernel=KERNEL) -> Float[Array, "T ... 3"]:
    """Axis-angles smoothed over time as sign-aligned quaternions."""
    q = rotvec_to_quat(rotvecs)
    acc = jnp.zeros_like(q)
    for offset, w in _weights(valid, kernel):
        qn = _shifted(q, offset)
        sign = jnp.where(jnp.sum(qn * q, axis=-1, keepdims=True) < 0, -1.0, 1.0)
        acc = acc + _expand(w, q) * sign * qn
    norm = jnp.linalg.norm(acc, axis=-1, keepdims=True)
    out = quat_to_rotvec(acc / jnp.where(norm > 0, norm, 1.0))
    return jnp.where(_expand(valid, rotvecs) & (norm > 0), out, rotvecs)


def smooth_params(params: SMPLXParams, valid: Bool[Array, "T"], kernel=KERNEL) -> SMPLXParams:
    """Every rotation of a batch of bodies (T leading) smoothed as rotations; shape, expression, ``transl``
    linearly. The 55 joints' rotations go through one conversion to quaternions and back, the rest through one
    average: the values of smoothing each field alone (to float32 rounding), compiled in a quarter of the time."""
    p = smooth_rotvecs(jax.vmap(SMPLXParams.full_pose)(params), valid, kernel)  # (T, 55, 3), SMPL-X order
    sizes = np.cumsum([params.betas.shape[-1], params.expression.shape[-1]])
    betas, expression, transl = jnp.split(smooth_linear(
        jnp.concatenate([params.betas, params.expression, params.transl], -1), valid, kernel), sizes, -1)
    return jax.vmap(params_of, in_axes=(0, 0, None))(p, betas, expression.shape[-1]).replace(
        expression=expression, transl=transl)


def smooth_camera(scale: Float[Array, "T"], trans: Float[Array, "T 2"], valid: Bool[Array, "T"], kernel=KERNEL):
    """A weak-perspective camera's ``scale`` and ``trans`` smoothed as `smooth_linear` does."""
    return smooth_linear(scale, valid, kernel), smooth_linear(trans, valid, kernel)
