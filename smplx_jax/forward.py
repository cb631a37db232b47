"""Forward passes of one body: the whole mesh (`forward`) and the joints alone (`forward_joints`).

The computation is the ``smplx`` package's: shape blend shapes, joints regressed from the shaped mesh
(precomputed as joint templates plus joint shape directions), pose blend shapes, a rigid kinematic chain and
linear blend skinning; then vertex joints and face landmarks, and ``transl`` last. Batch with ``jax.vmap``.

The three public functions are jitted: called eagerly, each runs one program compiled once per shape, not its
hundred operations one by one (slower both the first time and after: docs/BENCHMARKS.md, "Body model").
Inside a caller's ``jit``, ``vmap`` or ``grad`` they are traced as any function is.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from smplx_jax.model import BodyModel
from smplx_jax.params import SMPLXParams
from smplx_jax.rotations import rotvec_to_rotmat


class Output(NamedTuple):
    """One body from `forward`: its mesh and its 127 joints (SMPL-X order), metres."""

    vertices: Float[Array, "V 3"]
    joints: Float[Array, "127 3"]


class Skeleton(NamedTuple):
    """The posed skeleton: global rotation and position of every joint (``transl`` included)."""

    glob_rotmats: Float[Array, "55 3 3"]
    joints: Float[Array, "55 3"]


# 3x3 products as three broadcast terms: XLA fuses them into one loop, faster on CPU than a broadcast-and-reduce
# or a batched dot of tiny matrices, in a program several times smaller than nine entries written out.
def _matmul3(a, b):
    return sum(a[..., :, k, None] * b[..., None, k, :] for k in range(3))


def _matvec3(a, v):
    return sum(a[..., :, k] * v[..., None, k] for k in range(3))


class _Levels(NamedTuple):
    """The joints in order of depth in the tree (``order``), each depth a slice of it (``bounds``), the parents of
    each depth as places in the depth above (``parent_slots``), and each joint's place in ``order`` (``place``)."""

    order: tuple[int, ...]
    bounds: tuple[tuple[int, int], ...]
    parent_slots: tuple[tuple[int, ...], ...]
    place: tuple[int, ...]


def _levels(parents: tuple[int, ...]) -> _Levels:
    """The joints grouped by depth in the tree (found as a function is traced: no program holds it)."""
    depth = [0] * len(parents)
    for j in range(1, len(parents)):
        depth[j] = depth[parents[j]] + 1
    groups = [[j for j in range(len(parents)) if depth[j] == d] for d in range(max(depth) + 1)]
    order = [j for group in groups for j in group]
    place = np.argsort(order).tolist()
    starts = np.cumsum([0] + [len(g) for g in groups])
    bounds = tuple((int(a), int(b)) for a, b in zip(starts[:-1], starts[1:]))
    parent_slots = tuple(tuple(place[parents[j]] - starts[d - 1] for j in groups[d]) for d in range(1, len(groups)))
    return _Levels(tuple(order), bounds, parent_slots, tuple(place))


def kinematic_chain(rel_rotmats: Float[Array, "J 3 3"], rest_joints: Float[Array, "J 3"], parents: tuple[int, ...]):
    """Global rotations and positions of the joints, ``G_i = G_parent [R_i | J_i - J_parent]``, one depth of the
    tree at a time; joints are gathered into depth order once and back once (no scatter: on CPU each is a kernel
    of its own, in the program and in its derivatives)."""
    levels = _levels(parents)
    order, place = np.array(levels.order), np.array(levels.place)  # fresh arrays: a cached constant keeps its dtype
    offsets = (rest_joints - rest_joints[np.maximum(np.array(parents), 0)])[order]
    rel_rotmats = rel_rotmats[order]
    rotmats, positions = [rel_rotmats[:1]], [rest_joints[:1]]
    for (start, stop), slots in zip(levels.bounds[1:], levels.parent_slots):
        slots = np.array(slots)
        parent_rotmats = rotmats[-1][slots]
        rotmats.append(_matmul3(parent_rotmats, rel_rotmats[start:stop]))
        positions.append(_matvec3(parent_rotmats, offsets[start:stop]) + positions[-1][slots])
    return jnp.concatenate(rotmats)[place], jnp.concatenate(positions)[place]


# Up to this many joints per vertex, skinning gathers each vertex's joints' transforms; beyond, one dense
# product with all the weights is faster (a model file with dense weights).
MAX_GATHERED_JOINTS = 8


def _skinning_transforms(glob_rotmats, positions, rest_joints) -> Float[Array, "12 J"]:
    """Per-joint skinning transforms ``[G_R | G_t - G_R J]`` as columns: 9 rotation entries, then 3 translation."""
    translations = positions - _matvec3(glob_rotmats, rest_joints)
    return jnp.concatenate([glob_rotmats.reshape(-1, 9), translations], axis=-1).T


def _gathered_blend(transforms, joints, weights) -> Float[Array, "12 N"]:
    """Blend of each point's transforms, from its joints ``(I, N)`` and weights ``(I, N)``."""
    return sum(weights[i] * transforms[:, joints[i]] for i in range(joints.shape[0]))


def _skin(blended, points_cm, axis: int):
    """Rest-pose points ``(3, N)`` moved by their blended transforms ``(12, N)``; coordinates along ``axis``."""
    x, y, z = points_cm
    return jnp.stack([blended[3 * c] * x + blended[3 * c + 1] * y + blended[3 * c + 2] * z + blended[9 + c]
                      for c in range(3)], axis=axis)


def _posed_points(template_cm, shapedirs_cm, posedirs_cm, shape, rel_rotmats):
    """Rest-pose points ``(3, N)`` with shape and pose blend shapes."""
    offsets = shape @ shapedirs_cm + _pose_feature(rel_rotmats) @ posedirs_cm
    return template_cm + offsets.reshape(3, -1)


def _pose_feature(rel_rotmats):
    return (rel_rotmats[1:] - jnp.eye(3, dtype=rel_rotmats.dtype)).reshape(-1)


@jax.jit  # traced once per shape and reused at every call site (retracing it was most of a run's tracing)
def _posed_skeleton(model: BodyModel, params: SMPLXParams):
    shape = params.shape_components()
    rel_rotmats = rotvec_to_rotmat(params.full_pose())
    rest_joints = model.joint_template + model.joint_shapedirs @ shape
    glob_rotmats, positions = kinematic_chain(rel_rotmats, rest_joints, model.parents)
    return shape, rel_rotmats, rest_joints, glob_rotmats, positions


def _joints(model, shape, rel_rotmats, transforms, positions, transl):
    """The 127 joints: skeleton, vertex joints, landmarks (barycentric in their triangles); of the mesh, only
    the vertices that vertex joints and landmarks read are shaped, posed and skinned."""
    points = _posed_points(model.sparse_template_cm, model.sparse_shapedirs_cm, model.sparse_posedirs_cm, shape,
                           rel_rotmats)
    vertices = _skin(_gathered_blend(transforms, model.sparse_skin_joints, model.sparse_skin_weights), points, 0)
    vertex_joints = vertices[:, model.vertex_joint_slots]
    landmarks = sum(model.landmark_bary[:, k] * vertices[:, model.landmark_slots[:, k]] for k in range(3))
    return jnp.concatenate([positions, vertex_joints.T, landmarks.T]) + transl


@jax.jit
def forward(model: BodyModel, params: SMPLXParams) -> Output:
    """Vertices (V, 3) and the 127 joints of one body, as ``smplx.SMPLX`` computes them."""
    shape, rel_rotmats, rest_joints, glob_rotmats, positions = _posed_skeleton(model, params)
    transforms = _skinning_transforms(glob_rotmats, positions, rest_joints)
    points = _posed_points(model.template_cm, model.shapedirs_cm, model.posedirs_cm, shape, rel_rotmats)
    if model.skin_joints.shape[0] <= MAX_GATHERED_JOINTS:
        blended = _gathered_blend(transforms, model.skin_joints, model.skin_weights)
    else:
        blended = transforms @ model.weights_t
    vertices = _skin(blended, points, -1) + params.transl
    return Output(vertices, _joints(model, shape, rel_rotmats, transforms, positions, params.transl))


@jax.jit
def forward_joints(model: BodyModel, params: SMPLXParams) -> Float[Array, "127 3"]:
    """The 127 joints of `forward` without forming the mesh."""
    shape, rel_rotmats, rest_joints, glob_rotmats, positions = _posed_skeleton(model, params)
    transforms = _skinning_transforms(glob_rotmats, positions, rest_joints)
    return _joints(model, shape, rel_rotmats, transforms, positions, params.transl)


@jax.jit
def posed_skeleton(model: BodyModel, params: SMPLXParams) -> Skeleton:
    """Global joint rotations and positions of one posed body (what copy-and-paste and IK need)."""
    _, _, _, glob_rotmats, positions = _posed_skeleton(model, params)
    return Skeleton(glob_rotmats, positions + params.transl)
