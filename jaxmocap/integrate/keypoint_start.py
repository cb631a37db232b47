"""A start for a fit to 2D keypoints alone (no 3D landmarks): the fit's default pose (`fitting.default_pose`,
upright, facing the camera) turned in the image plane to lie along the torso the keypoints show, and turned round
when they show its back.

Which side of the torso faces the camera is the one thing one image shows unambiguously of its orientation: seen
from the front, a body's left (OpenPose's 5 and 12) lies to the image's right of its up direction (hips to
shoulders); seen from behind, to its left (the sign of the 2D cross product, whatever the camera's roll). Turns
about the vertical between those two (a body seen edge-on) are the fit's to find.
"""

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from jaxmocap.integrate.fitting import default_pose
from smplx_jax.rotations import rotmat_to_rotvec, rotvec_to_rotmat

SHOULDERS, HIPS = (2, 5), (9, 12)  # OpenPose BODY_25: (right, left)
NECK, MID_HIP = 1, 8


def _centre(keypoints, pair, fallback):
    """The mean of the seen keypoints of ``pair``, else keypoint ``fallback``; and whether either was seen."""
    seen = keypoints[list(pair), 2] > 0
    mean = jnp.sum(jnp.where(seen[:, None], keypoints[list(pair), :2], 0.0), 0) / jnp.maximum(jnp.sum(seen), 1)
    fallback_seen = keypoints[fallback, 2] > 0
    return jnp.where(jnp.any(seen), mean, keypoints[fallback, :2]), jnp.any(seen) | fallback_seen


def facing_pose(keypoints: Float[ArrayLike, "67 3"]) -> Float[Array, "55 3"]:
    """``(55, 3)`` the default pose with its global orientation turned about the camera's axis so that its torso
    points from the hips to the shoulders the keypoints show (upright where either is missing), then about its
    own vertical by half a turn where the keypoints show its back (module docstring; facing the camera where they
    do not tell). Pure: jit and vmap over frames."""
    keypoints = jnp.asarray(keypoints)
    shoulders, shoulders_seen = _centre(keypoints, SHOULDERS, NECK)
    hips, hips_seen = _centre(keypoints, HIPS, MID_HIP)
    up = jnp.where(shoulders_seen & hips_seen, shoulders - hips, jnp.asarray([0.0, -1.0]))
    up = jnp.where(jnp.linalg.norm(up) > 0, up, jnp.asarray([0.0, -1.0]))
    roll = jnp.arctan2(up[0], -up[1])  # about the camera's z (into the image) from the image's up (0, -1)
    leftward = jnp.zeros(2)
    for right, left in (SHOULDERS, HIPS):
        both = (keypoints[left, 2] > 0) & (keypoints[right, 2] > 0)
        leftward = leftward + jnp.where(both, keypoints[left, :2] - keypoints[right, :2], 0.0)
    back = leftward[0] * up[1] - leftward[1] * up[0] > 0  # the body's left on the image's left of its up
    pose = default_pose(keypoints.dtype)
    turn = jnp.stack([jnp.zeros(()), jnp.where(back, np.pi, 0.0), jnp.zeros(())]).astype(keypoints.dtype)
    image = jnp.stack([jnp.zeros(()), jnp.zeros(()), roll]).astype(keypoints.dtype)
    orient = rotvec_to_rotmat(image) @ rotvec_to_rotmat(pose[0]) @ rotvec_to_rotmat(turn)
    return pose.at[0].set(rotmat_to_rotvec(orient))
