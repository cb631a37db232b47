"""The hand model H (FrankMocap Eq. 3-4): one hand of an SMPL-X model used on its own, the wrist as root.

Its vertices are those whose dominant skinning joint is the wrist or a finger joint of that hand. Skinning
weights on other joints (the forearm side of the wrist) are moved to the wrist: the hand carries them
rigidly. Pose blend shapes keep the finger joints' columns.
"""

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from smplx_jax import constants
from smplx_jax.forward import _posed_points, _skin, _skinning_transforms, kinematic_chain
from smplx_jax.model import BodyModel, device_array
from smplx_jax.params import Side
from smplx_jax.pytree import pytree_dataclass
from smplx_jax.rotations import rotvec_to_rotmat

# The 21 hand joints in OpenPose order, as indices into [wrist, 15 finger joints (SMPL-X order), 5 tips
# (thumb, index, middle, ring, pinky)].
_OPENPOSE_ORDER = (0, 13, 14, 15, 16, 1, 2, 3, 17, 4, 5, 6, 18, 10, 11, 12, 19, 7, 8, 9, 20)


@pytree_dataclass
@dataclasses.dataclass(frozen=True)
class HandModel:
    """One hand. ``N`` vertices; joint 0 is the wrist, 1..15 the finger joints in SMPL-X order."""

    vertex_ids: Int[Array, "N"]  # ids in the body model
    faces: Int[Array, "F 3"]  # into the N hand vertices
    template_cm: Float[Array, "3 N"]  # coordinate-major, as in `BodyModel`
    shapedirs_cm: Float[Array, "B 3*N"]
    posedirs_cm: Float[Array, "135 3*N"]
    weights_t: Float[Array, "16 N"]
    joint_template: Float[Array, "16 3"]
    joint_shapedirs: Float[Array, "16 3 B"]
    tip_slots: Int[Array, "5"]  # fingertip vertices (thumb..pinky) among the N
    parents: tuple[int, ...] = dataclasses.field(metadata=dict(static=True))


class HandOutput(NamedTuple):
    """One hand from `hand_forward`: its mesh and 21 joints (OpenPose hand order), metres."""

    vertices: Float[Array, "N 3"]
    joints: Float[Array, "21 3"]  # OpenPose hand order


def hand_model(model: BodyModel, side: Side) -> HandModel:
    """The hand model H of one side of a body model."""
    wrist = constants.LEFT_WRIST if side == "left" else constants.RIGHT_WRIST
    fingers = constants.LEFT_HAND_JOINTS if side == "left" else constants.RIGHT_HAND_JOINTS
    hand_joints = np.array((wrist,) + fingers)
    tips = np.array(constants.VERTEX_JOINT_IDS[11:16] if side == "left" else constants.VERTEX_JOINT_IDS[16:21])

    weights = np.asarray(model.weights_t).T
    dominant = np.argmax(weights, axis=1)
    vertex_ids = np.union1d(np.flatnonzero(np.isin(dominant, hand_joints)), tips)
    hand_weights = weights[vertex_ids][:, hand_joints]
    hand_weights[:, 0] += weights[vertex_ids].sum(axis=1) - hand_weights.sum(axis=1)

    faces = np.asarray(model.faces)
    local = np.full(model.num_vertices, -1)
    local[vertex_ids] = np.arange(len(vertex_ids))
    hand_faces = local[faces[np.all(local[faces] >= 0, axis=1)]]

    feature_rows = ((np.array(fingers)[:, None] - 1) * 9 + np.arange(9)).ravel()
    cols = (np.arange(3)[:, None] * model.num_vertices + vertex_ids).ravel()  # coordinate-major columns
    index = {j: i for i, j in enumerate(hand_joints)}
    parents = (-1,) + tuple(index[model.parents[j]] for j in fingers)
    dtype = model.template_cm.dtype
    # (cut by NumPy: as JAX operations, each would be a program of its own)
    return HandModel(
        vertex_ids=device_array(vertex_ids, jnp.int32),
        faces=device_array(hand_faces, jnp.int32),
        template_cm=device_array(np.asarray(model.template_cm)[:, vertex_ids], dtype),
        shapedirs_cm=device_array(np.asarray(model.shapedirs_cm)[: model.num_betas, cols], dtype),
        posedirs_cm=device_array(np.asarray(model.posedirs_cm)[feature_rows][:, cols], dtype),
        weights_t=device_array(hand_weights.T, dtype),
        joint_template=device_array(np.asarray(model.joint_template)[hand_joints], dtype),
        joint_shapedirs=device_array(np.asarray(model.joint_shapedirs)[hand_joints][..., : model.num_betas], dtype),
        tip_slots=device_array(np.searchsorted(vertex_ids, tips), jnp.int32),
        parents=parents,
    )


@jax.jit  # as `smplx_jax.forward`: one compiled program per shape when called eagerly
def hand_forward(
    hand: HandModel,
    wrist_glob_rotmat: Float[Array, "3 3"],
    hand_pose: Float[Array, "15 3"],
    betas: Float[Array, "B"],
) -> HandOutput:
    """Hand vertices and 21 OpenPose-order joints for a global wrist rotation, absolute finger axis-angles
    and body shape; the wrist joint is at the origin."""
    rest_joints = hand.joint_template + hand.joint_shapedirs @ betas
    rel_rotmats = jnp.concatenate([wrist_glob_rotmat[None], rotvec_to_rotmat(hand_pose)])
    glob_rotmats, positions = kinematic_chain(rel_rotmats, rest_joints, hand.parents)
    points = _posed_points(hand.template_cm, hand.shapedirs_cm, hand.posedirs_cm, betas, rel_rotmats)
    blended = _skinning_transforms(glob_rotmats, positions, rest_joints) @ hand.weights_t
    vertices = _skin(blended, points, -1) - positions[0]
    joints = jnp.concatenate([positions - positions[0], vertices[hand.tip_slots]])
    return HandOutput(vertices, joints[jnp.array(_OPENPOSE_ORDER)])

