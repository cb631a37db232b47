"""The One-Euro filter (Casiez, Roussel and Vogel, CHI 2012), causal: a low-pass whose cutoff rises with speed,
so that a still body does not jitter and a moving one does not lag. Rotations are filtered as unit quaternions,
each sign-aligned to the last output (q and -q are one rotation) and normalised. Pure JAX functions."""

from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
from jaxtyping import Array, Float

from smplx_jax.rotations import quat_to_rotvec, rotvec_to_quat


@dataclass(frozen=True)
class OneEuro:
    """``min_cutoff`` (Hz): the cutoff at rest; ``beta`` (Hz per unit/s): how fast it rises with speed;
    ``d_cutoff`` (Hz): the cutoff of the speed estimate."""

    min_cutoff: float = 1.0
    beta: float = 0.0
    d_cutoff: float = 1.0


class Filtered(NamedTuple):
    """A filter's state: the last output ``(..., D)`` and the speed of each row ``(...)``, per second."""

    value: Float[Array, "*rows D"]
    speed: Float[Array, "*rows"]


def _alpha(cutoff, dt):
    return 1.0 / (1.0 + 1.0 / (2 * jnp.pi * cutoff * dt))


def one_euro(values: Float[Array, "*rows D"], state: Filtered, dt, settings: OneEuro
             ) -> tuple[Float[Array, "*rows D"], Filtered]:
    """The filtered ``values`` and the new state, ``dt`` seconds after ``state``'s; the speed of a row is its
    vector's (the norm over the last axis). Start a filter with ``Filtered(values, zeros)``."""
    speed = jnp.linalg.norm(values - state.value, axis=-1) / dt
    speed = state.speed + _alpha(settings.d_cutoff, dt) * (speed - state.speed)
    alpha = _alpha(settings.min_cutoff + settings.beta * speed, dt)[..., None]
    out = state.value + alpha * (values - state.value)
    return out, Filtered(out, speed)


def one_euro_rotvecs(rotvecs: Float[Array, "*rows 3"], state: Filtered, dt, settings: OneEuro
                     ) -> tuple[Float[Array, "*rows 3"], Filtered]:
    """`one_euro` of axis-angles as quaternions: ``state`` holds quaternions (`quaternion_state`)."""
    quats = rotvec_to_quat(rotvecs)
    quats = jnp.where(jnp.sum(quats * state.value, axis=-1, keepdims=True) < 0, -quats, quats)
    out, state = one_euro(quats, state, dt, settings)
    out = out / jnp.maximum(jnp.linalg.norm(out, axis=-1, keepdims=True), 1e-12)
    return quat_to_rotvec(out), state._replace(value=out)


def start_state(values: Float[Array, "*rows D"]) -> Filtered:
    """A filter at rest on ``values``."""
    return Filtered(values, jnp.zeros(values.shape[:-1], values.dtype))


def quaternion_state(rotvecs: Float[Array, "*rows 3"]) -> Filtered:
    """A rotation filter at rest on ``rotvecs``."""
    return start_state(rotvec_to_quat(rotvecs))
