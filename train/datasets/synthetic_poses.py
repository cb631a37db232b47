"""Random plausible SMPL-X parameters for the synthetic datasets (numpy, one example per call)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

from smplx_jax import constants
from smplx_jax.rotations import rotmat_to_rotvec, rotvec_to_rotmat

# Per-axis limits (radians) of the body joints' local axis-angle, SMPL-X frame (x: the body's left, y: up,
# z: forward). Left-side joints; the right side mirrors them (y and z negated).
_J = {name: i for i, name in enumerate(constants.JOINT_NAMES)}
_LEFT_LIMITS = {
    "hip": ((-1.6, 0.4), (-0.5, 0.5), (-0.2, 0.7)),
    "knee": ((0.0, 2.0), (-0.05, 0.05), (-0.05, 0.05)),
    "ankle": ((-0.4, 0.5), (-0.2, 0.2), (-0.2, 0.2)),
    "foot": ((-0.1, 0.1), (-0.1, 0.1), (-0.1, 0.1)),
    "collar": ((-0.1, 0.1), (-0.2, 0.2), (-0.3, 0.2)),
    "shoulder": ((-0.8, 0.8), (-1.3, 0.5), (-1.4, 0.6)),
    "elbow": ((-0.3, 0.3), (-2.3, 0.0), (-0.1, 0.1)),
    "wrist": ((-0.5, 0.5), (-0.4, 0.4), (-0.6, 0.6)),
}
_CENTRE_LIMITS = {
    "spine1": ((-0.3, 0.6), (-0.3, 0.3), (-0.2, 0.2)),
    "spine2": ((-0.2, 0.3), (-0.2, 0.2), (-0.15, 0.15)),
    "spine3": ((-0.2, 0.3), (-0.2, 0.2), (-0.15, 0.15)),
    "neck": ((-0.4, 0.5), (-0.5, 0.5), (-0.3, 0.3)),
    "head": ((-0.4, 0.5), (-0.6, 0.6), (-0.3, 0.3)),
}


def _body_limits() -> Float[np.ndarray, "21 3 2"]:
    limits = np.zeros((22, 3, 2))
    for name, lim in _CENTRE_LIMITS.items():
        limits[_J[name]] = lim
    for name, lim in _LEFT_LIMITS.items():
        limits[_J[f"left_{name}"]] = lim
        mirrored = np.array(lim) * [[1], [-1], [-1]]
        limits[_J[f"right_{name}"]] = np.sort(mirrored, axis=1)
    return limits[1:]


BODY_POSE_LIMITS = _body_limits()
_CAMERA_FROM_MODEL = np.array([np.pi, 0.0, 0.0])  # y up, facing +z  ->  y down, facing the camera


@jax.jit
def _product(rotvecs: Float[jax.Array, "N 3"]) -> Float[jax.Array, "3"]:
    return rotmat_to_rotvec(functools.reduce(jnp.matmul, rotvec_to_rotmat(rotvecs)))


def _composed(*rotvecs: Float[np.ndarray, "3"]) -> Float[np.ndarray, "3"]:
    """Axis-angle of the product of the rotations ``rotvecs`` (the last applied first)."""
    return np.asarray(_product(jnp.asarray(np.stack(rotvecs), jnp.float32)))


HAND_MEAN_ROTVEC = np.array([np.pi / 2, 0.0, 0.0])
"""The synthetic hands' mean camera-frame wrist orientation: SMPL-X's rest hand (palm down, y up) turned so its palm
faces the camera."""
HAND_MAX_TURN = 1.4
"""Largest turn (rad) away from `HAND_MEAN_ROTVEC`: palm, back and side views, never near the axis-angle
wrap-around at pi."""


def random_hand_orientation(rng: np.random.Generator) -> Float[np.ndarray, "3"]:
    """A camera-frame wrist axis-angle: the mean orientation turned about a uniformly random axis by an angle
    uniform in [0, `HAND_MAX_TURN`]."""
    axis = rng.normal(size=3)
    return _composed(rng.uniform(0.0, HAND_MAX_TURN) * axis / np.linalg.norm(axis), HAND_MEAN_ROTVEC)


def random_hand_pose(
    rng: np.random.Generator, mean: Float[np.ndarray, "45"], components: Float[np.ndarray, "C 45"]
) -> Float[np.ndarray, "15 3"]:
    """Absolute finger axis-angles ``mean + coeffs @ components[:6]`` (``hand_pose_from_pca``) with coefficients
    of decreasing spread, plus a little per-joint noise; each joint's rotation is capped at 1.8 rad."""
    spread = np.array([1.1, 0.6, 0.45, 0.35, 0.3, 0.25])[: len(components)]
    coeffs = rng.normal(0.0, spread)
    pose = (mean + coeffs @ components[: len(spread)]).reshape(15, 3) + rng.normal(0.0, 0.05, (15, 3))
    angle = np.linalg.norm(pose, axis=1, keepdims=True)
    return pose * np.minimum(1.0, 1.8 / np.maximum(angle, 1e-12))


def random_body_pose(rng: np.random.Generator) -> Float[np.ndarray, "21 3"]:
    """Per-joint axis-angle drawn within `BODY_POSE_LIMITS`, scaled towards rest by a random amount."""
    lo, hi = BODY_POSE_LIMITS[..., 0], BODY_POSE_LIMITS[..., 1]
    pose = rng.uniform(lo, hi)
    return pose * rng.uniform(0.3, 1.0)


def random_body_orientation(rng: np.random.Generator) -> Float[np.ndarray, "3"]:
    """Camera-frame global axis-angle of a mostly upright body at a random yaw."""
    yaw = np.array([0.0, rng.uniform(0, 2 * np.pi), 0.0])
    tilt = rng.normal(0.0, 0.12, 3) * [1, 0, 1]
    return _composed(_CAMERA_FROM_MODEL, tilt, yaw)
