"""Cameras (docs/formats.md, "Coordinates and cameras"; x right, y down, z away from the camera): weak
perspective ``pixel = camera_scale * X[..., :2] + camera_trans``, or a pinhole
``pixel = focal_length * X[..., :2] / X[..., 2:] + principal_point`` of camera-frame points (metres; what the fit
of the default pipeline uses, motion.npz's ``focal_length`` and ``principal_point``)."""

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float


def project(points: Float[ArrayLike, "... N 3"], scale: Float[ArrayLike, "..."], trans: Float[ArrayLike, "... 2"],
            focal_length=None, principal_point=None):
    """Pixels ``(..., N, 2)`` of model points under the pinhole camera when ``focal_length`` is given, else the
    weak-perspective one."""
    if focal_length is not None:
        return focal_length * points[..., :2] / points[..., 2:] + jnp.asarray(principal_point)
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


def weak_perspective_least_squares(points_xy: Float[Array, "N 2"], pixels: Float[Array, "N 2"],
                                   weights: Float[Array, "N"]) -> tuple[Array, Array]:
    """The scale and translation of least weighted squared error from ``points_xy`` to ``pixels``; ``(1.0, 0)``
    when fewer than two weighted points spread apart."""
    wsum = jnp.maximum(jnp.sum(weights), 1e-12)
    pc = jnp.sum(weights[:, None] * points_xy, 0) / wsum
    tc = jnp.sum(weights[:, None] * pixels, 0) / wsum
    spread = jnp.sum(weights * jnp.sum((points_xy - pc) ** 2, -1))
    ok = spread > 1e-12
    scale = jnp.where(ok, jnp.sum(weights * jnp.sum((points_xy - pc) * (pixels - tc), -1)) / jnp.where(ok, spread, 1.0),
                      1.0)
    return scale, jnp.where(ok, tc - scale * pc, jnp.zeros_like(tc))


def default_focal_length(image_size) -> float:
    """Focal length in pixels of a phone's main camera (26 mm full-frame equivalent: the long side of a 4:3
    sensor spans 67 degrees; 16:9 video crops the short side) for an image of ``(width, height)``."""
    return 0.75 * max(image_size)
