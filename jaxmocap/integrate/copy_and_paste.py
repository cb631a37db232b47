"""Copy-and-paste integration (FrankMocap Eq. 11-12): hands' finger poses into the body, each hand's global wrist
orientation converted to the body's local wrist rotation, ``R_wrist_local = R_parent_global^T R_hand_global``.
Shape and camera stay the body's. One body; batch with `jax.vmap`."""

import jax.numpy as jnp
from jaxtyping import Array, Float

from smplx_jax import BodyModel, SMPLXParams, constants, posed_skeleton
from smplx_jax.rotations import rotmat_to_rotvec, rotvec_to_rotmat

# Parent of each wrist (the elbow): chains 0-3-6-9-13-16-18(-20) and 0-3-6-9-14-17-19(-21).
LEFT_ELBOW, RIGHT_ELBOW = 18, 19


def wrist_local_rotvecs(model: BodyModel, body: SMPLXParams, left_wrist_global: Float[Array, "3 3"],
                        right_wrist_global: Float[Array, "3 3"]) -> tuple[Array, Array]:
    """Local axis-angles of the left and right wrists that give the wrists these global rotations under the
    body's forward kinematics."""
    glob = posed_skeleton(model, body).glob_rotmats
    left = glob[LEFT_ELBOW].T @ left_wrist_global
    right = glob[RIGHT_ELBOW].T @ right_wrist_global
    return rotmat_to_rotvec(left), rotmat_to_rotvec(right)


def copy_paste(model: BodyModel, body: SMPLXParams, left_hand_pose: Float[Array, "15 3"],
               left_wrist_global: Float[Array, "3"], right_hand_pose: Float[Array, "15 3"],
               right_wrist_global: Float[Array, "3"]) -> SMPLXParams:
    """The body with both hands pasted in. Hand poses are absolute finger axis-angles (SMPL-X order); wrist
    orientations are global axis-angles in the body's world frame (the frame of ``body.global_orient``)."""
    left, right = wrist_local_rotvecs(model, body, rotvec_to_rotmat(left_wrist_global),
                                      rotvec_to_rotmat(right_wrist_global))
    body_pose = body.body_pose.at[constants.LEFT_WRIST - 1].set(left).at[constants.RIGHT_WRIST - 1].set(right)
    return body.replace(body_pose=body_pose, left_hand_pose=jnp.asarray(left_hand_pose, body.body_pose.dtype),
                        right_hand_pose=jnp.asarray(right_hand_pose, body.body_pose.dtype))
