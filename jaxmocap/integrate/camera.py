"""Weak-perspective camera (DESIGN 2.3): ``pixel = camera_scale * X[..., :2] + camera_trans``, x right, y down."""

import jax.numpy as jnp
from jaxtyping import Array, Float


def project(points: Float[Array, "... N 3"], scale: Float[Array, "..."], trans: Float[Array, "... 2"]):
    """Pixels ``(..., N, 2)`` of model points under the weak-perspective camera."""
    return scale[..., None, None] * points[..., :2] + trans[..., None, :]


def weak_perspective_from_points(model_xy: Float[Array, "N 2"], target_xy: Float[Array, "N 2"],
                                 weights: Float[Array, "N"]) -> tuple[Array, Array]:
    """Scale and translation that map the model points' weighted centre and RMS spread onto the targets'
    (rotation-free, so a rough initial pose still gets the right size). One body; ``(1.0, 0)`` when fewer than
    two weighted points spread apart."""
    wsum = jnp.maximum(jnp.sum(weights), 1e-12)
    mc = jnp.sum(weights[:, None] * model_xy, 0) / wsum
    tc = jnp.sum(weights[:, None] * target_xy, 0) / wsum
    ms = jnp.sum(weights * jnp.sum((model_xy - mc) ** 2, -1))
    ts = jnp.sum(weights * jnp.sum((target_xy - tc) ** 2, -1))
    ok = (ms > 1e-12) & (ts > 1e-12)
    scale = jnp.where(ok, jnp.sqrt(jnp.where(ok, ts / jnp.where(ok, ms, 1.0), 1.0)), 1.0)
    return scale, jnp.where(ok, tc - scale * mc, jnp.zeros_like(tc))
