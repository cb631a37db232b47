"""Named example poses of the SMPL-X skeleton, for demos, renders and tests."""

import jax.numpy as jnp
import numpy as np

from smplx_jax import SMPLXParams, constants

_J = {name: i for i, name in enumerate(constants.JOINT_NAMES)}


def example_pose(num_betas: int = 10, num_expression: int = 10) -> SMPLXParams:
    """Arms lowered with bent elbows, right hip and knee bent, head turned, jaw open, right fist."""
    full = np.zeros((55, 3), np.float32)
    full[_J["left_shoulder"]] = (0, 0, -1.2)
    full[_J["right_shoulder"]] = (0, 0, 1.2)
    full[_J["left_elbow"]] = (0, -1.3, 0)
    full[_J["right_elbow"]] = (0, 1.3, 0)
    full[_J["right_hip"]] = (-0.8, 0, 0)
    full[_J["right_knee"]] = (1.3, 0, 0)
    full[_J["head"]] = (0, 0.5, 0)
    full[_J["jaw"]] = (0.35, 0, 0)
    for finger in ("index", "middle", "ring", "pinky"):
        for k in (1, 2, 3):
            full[_J[f"right_{finger}{k}"]] = (0, 0, 1.3)
    full[_J["right_thumb2"]] = (0.4, 0.6, 0.3)
    full[_J["right_thumb3"]] = (0, 0.7, 0)
    zeros = SMPLXParams.zeros(num_betas, num_expression)
    return zeros.replace(
        global_orient=jnp.asarray(full[0]),
        body_pose=jnp.asarray(full[1:22]),
        jaw_pose=jnp.asarray(full[22]),
        left_hand_pose=jnp.asarray(full[25:40]),
        right_hand_pose=jnp.asarray(full[40:55]),
    )
