"""Model keypoints as a function of pose and shape, with an exact analytic Jacobian-vector product.

Fits solve for the 55 joint axis-angles and the shape ``betas`` of one body so that ``K`` of its 127 output joints
(skeleton joints and vertex joints; `keypoints_cm`, equal to `smplx_jax.forward_joints`) land on targets. The
Jacobian is geometric (`linearize` once per point, then `jvp` per direction, a few products each; `keypoints_cm`
carries it as its `jax.custom_jvp`, so that ``J^T`` comes by transposition and higher derivatives exist):

* Rotating joint ``j`` by a world-frame increment ``w_j = G_parent(j) J_l(theta_j) dtheta_j`` (``J_l`` SO(3)'s
  left Jacobian) moves a point rigidly attached below it by ``w_j x (x - p_j)``. A keypoint skinned to joints
  ``l`` with weights ``W_l`` moves by ``sum_l W_l (Omega_l x y_l - Q_l)``, ``y_l`` the point as joint ``l`` alone
  carries it, ``Omega_l`` and ``Q_l`` sums of ``w_j`` and ``w_j x p_j`` over the joints ``j`` at or above ``l``.
  Written as ``(sum_j reach[k, j] w_j) x x_k - sum_j reach[k, j] w_j x p_j`` plus a correction for the blended
  vertex keypoints, a batch of bodies shares the constant ``(K, 55)`` matrix ``reach``: one GEMM under `jax.vmap`.
* Shape moves the rest joints (through the kinematic chain) and the rest vertices.
* Pose blend shapes move vertex keypoints through ``(R_j - I)``; for a model whose blend shapes at those vertices
  are zero (the default model) the term is left out when the model is known at build time.
"""

from __future__ import annotations

import dataclasses
import weakref
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

import smplx_jax
from jaxmocap.integrate import mat3
from smplx_jax import BodyModel, SMPLXParams
from smplx_jax.model import device_array
from smplx_jax.pytree import pytree_dataclass

NUM_VERTEX_JOINTS = 21


def _static(**kwargs):
    return dataclasses.field(metadata=dict(static=True), **kwargs)


@pytree_dataclass
@dataclasses.dataclass(frozen=True)
class KeypointModel:
    """A body model reduced to what a fit to ``K`` keypoints needs (see `keypoint_model`). ``I`` is the most
    joints any vertex joint is skinned to, ``V = 21`` the vertex joints."""

    body: BodyModel  # sparse vertices trimmed to the vertex joints
    index: Int[Array, "K"]  # the keypoints as indices into the 127 output joints (< 76)
    reach: Float[Array, "K 55"]  # sum of keypoint k's skinning weights over the joints at or below j
    reach2: Float[Array, "K 55"]  # reach ** 2
    ancestors: Float[Array, "55 55"]  # [j, l] = 1 when j is l or an ancestor of l
    vertex_select: Float[Array, "21 K"]  # [v, k] = 1 when keypoint k is vertex joint v
    vertex_skin: Float[Array, "21 55"]  # skinning weights of the vertex joints
    blended: tuple[tuple[int, ...], tuple[int, ...]] = _static()  # (influence i >= 1, vertex joint v) pairs
    blended_reach: Float[Array, "55 P"]  # ancestors of the pair's joint minus those of v's first joint
    blended_select: Float[Array, "P K"]  # [pair, k] = 1 when keypoint k is the pair's vertex joint
    joint_shapedirs: Float[Array, "3 B 55"]  # of the rest joints
    parent_shapedirs: Float[Array, "3 B 55"]  # of each joint's parent (the root's own)
    vertex_shapedirs: Float[Array, "3 B 21"]  # of the vertex joints' rest vertices
    posedirs: Float[Array, "486 63"]  # pose blend shapes of the vertex joints, rows (r, c, joint 1..54)
    pose_correctives: bool = _static()  # whether ``posedirs`` can be nonzero

    @property
    def num_keypoints(self) -> int:
        return self.index.shape[0]


def _trimmed_body(model: BodyModel) -> BodyModel:
    """The same model with only the vertex-joint vertices kept (face landmarks are not fitted)."""
    slots = model.vertex_joint_slots
    cols = _columns(model, slots)
    return dataclasses.replace(
        model,
        sparse_ids=model.sparse_ids[slots],
        sparse_template_cm=model.sparse_template_cm[:, slots],
        sparse_shapedirs_cm=model.sparse_shapedirs_cm[:, cols],
        sparse_posedirs_cm=model.sparse_posedirs_cm[:, cols],
        sparse_skin_joints=model.sparse_skin_joints[:, slots],
        sparse_skin_weights=model.sparse_skin_weights[:, slots],
        vertex_joint_slots=device_array(np.arange(slots.shape[0]), jnp.int32),
        landmark_slots=jnp.zeros_like(model.landmark_slots),
    )


def _columns(model: BodyModel, slots):
    """The coordinate-major columns of the sparse vertices in ``slots`` (the sparse arrays' vertex order)."""
    return (np.arange(3)[:, None] * model.sparse_ids.shape[0] + slots).ravel()


def _known(a) -> np.ndarray | None:
    """The values of an array known at trace time (None for a traced one)."""
    try:
        return np.asarray(a)
    except jax.errors.TracerArrayConversionError:
        return None


def _blended_pairs(weights) -> tuple[tuple[int, ...], tuple[int, ...]]:
    """The skinning influences ``(i >= 1, v)`` of the vertex joints that can carry weight (all when traced)."""
    known = _known(weights)
    mask = np.ones((weights.shape[0] - 1, weights.shape[1]), bool) if known is None else known[1:] > 0
    i, v = np.nonzero(mask)
    return tuple(int(a) + 1 for a in i), tuple(int(b) for b in v)


_BUILT: dict[tuple, tuple[weakref.ref, KeypointModel]] = {}  # (id(model), index) -> (the model, its constants)


def keypoint_model(model: BodyModel, index) -> KeypointModel:
    """The fit's constants for keypoints ``index`` (a static sequence of indices into the 127 output joints:
    skeleton joints 0..54 and vertex joints 55..75). Works on a traced model too (inside `jax.jit`). Built once
    per concrete model and index, as one program (`_built`)."""
    index = np.asarray(index, dtype=np.int64)
    if any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves(model)):
        return _keypoint_model(model, index)  # a traced model: its constants belong to that trace
    key = (id(model), tuple(index.tolist()))
    ref, km = _BUILT.get(key, (None, None))
    if ref is None or ref() is not model:
        with jax.ensure_compile_time_eval():  # concrete constants, even when first asked for inside a trace
            km = _built(model, key[1], _concrete_structure(model))
        _BUILT[key] = (weakref.ref(model, lambda _, key=key: _BUILT.pop(key, None)), km)
    return km


def _structure(posedirs_cm, skin_weights) -> tuple[bool, tuple[tuple[int, ...], tuple[int, ...]]]:
    """What `_keypoint_model` reads from the vertex joints' values (all is assumed where they are traced): whether
    they have pose blend shapes, and their skinning influences that carry weight (`_blended_pairs`)."""
    known = _known(posedirs_cm)
    return known is None or bool(np.any(known)), _blended_pairs(skin_weights)


def _concrete_structure(model: BodyModel) -> tuple[bool, tuple[tuple[int, ...], tuple[int, ...]]]:
    """`_structure` of a concrete model, its vertex joints cut by NumPy (as JAX operations, programs of their own)."""
    slots = np.asarray(model.vertex_joint_slots)
    return _structure(np.asarray(model.sparse_posedirs_cm)[:, _columns(model, slots)],
                      np.asarray(model.sparse_skin_weights)[:, slots])


# A concrete model's constants as one program. As ~30 eager operations, each a program that a new process read back
# from the compile cache, a run's three keypoint sets took 0.75-0.86 s; as one program each, 0.33 s.
_built = jax.jit(lambda model, index, structure: _keypoint_model(model, np.asarray(index), structure),
                 static_argnums=(1, 2))


def _keypoint_model(model: BodyModel, index: np.ndarray, structure=None) -> KeypointModel:
    """``structure``: `_concrete_structure` of the model (`_built` traces it, so cannot read its values); None:
    `_structure` of its trimmed body."""
    nj = len(model.parents)
    if index.ndim != 1 or index.min() < 0 or index.max() >= nj + NUM_VERTEX_JOINTS:
        raise ValueError(f"keypoint indices must be skeleton joints (0..{nj - 1}) or vertex joints "
                         f"({nj}..{nj + NUM_VERTEX_JOINTS - 1}), got {index.tolist()}")
    dtype = model.joint_template.dtype
    ancestors = np.eye(nj)
    for joint in range(nj):
        j = model.parents[joint]
        while j >= 0:
            ancestors[j, joint] = 1.0
            j = model.parents[j]
    body = _trimmed_body(model)
    nb = model.num_betas
    skeleton = index[:, None] == np.arange(nj)  # (K, 55) one-hot
    vertex = index[:, None] == nj + np.arange(NUM_VERTEX_JOINTS)  # (K, 21) one-hot
    vertex_skin = model.weights_t[:, body.sparse_ids].T  # (21, 55)
    skin = device_array(skeleton, dtype) + device_array(vertex, dtype) @ vertex_skin  # (K, 55)
    reach = skin @ device_array(ancestors.T, dtype)
    joint_sd = model.joint_shapedirs[..., :nb]  # (55, 3, B)
    def cm(a):  # (N, 3, B) -> (3, B, N)
        return jnp.transpose(a, (1, 2, 0))
    posedirs = body.sparse_posedirs_cm.reshape(nj - 1, 3, 3, 3 * NUM_VERTEX_JOINTS)  # rows (joint, r, c)
    posedirs = jnp.transpose(posedirs, (1, 2, 0, 3)).reshape(9 * (nj - 1), 3 * NUM_VERTEX_JOINTS)
    pose_correctives, blended = (_structure(body.sparse_posedirs_cm, body.sparse_skin_weights) if structure is None
                                 else structure)
    anc = device_array(ancestors, dtype)
    joints = body.sparse_skin_joints
    return KeypointModel(
        body=body, index=device_array(index, jnp.int32), reach=reach, reach2=reach**2, ancestors=anc,
        joint_shapedirs=cm(joint_sd), parent_shapedirs=cm(joint_sd[np.maximum(np.asarray(model.parents), 0)]),
        vertex_shapedirs=body.sparse_shapedirs_cm[:nb].reshape(nb, 3, NUM_VERTEX_JOINTS).transpose(1, 0, 2),
        posedirs=posedirs, pose_correctives=pose_correctives,
        vertex_select=device_array(vertex.T, dtype), vertex_skin=vertex_skin, blended=blended,
        blended_reach=anc[:, joints[blended]] - anc[:, joints[0, np.asarray(blended[1], int)]],
        blended_select=device_array(vertex.T[np.asarray(blended[1], int)], dtype))


def params_of(pose_rotvecs: Float[Array, "55 3"], betas: Float[Array, "B"], num_expression: int) -> SMPLXParams:
    """One body's `SMPLXParams` from its full pose (SMPL-X joint order), shape, no expression, no translation."""
    p = pose_rotvecs
    z = jnp.zeros(3, p.dtype)
    return SMPLXParams(p[0], p[1:22], p[25:40], p[40:55], p[22], p[23], p[24], betas,
                       jnp.zeros(num_expression, p.dtype), z)


class _Posed(NamedTuple):
    glob: Float[Array, "3 3 55"]  # global joint rotations
    p: Float[Array, "3 55"]  # joint positions
    rel: Float[Array, "3 3 55"]  # local joint rotations
    carried: Float[Array, "3 I 21"]  # each vertex joint's rest vertex as each of its joints carries it
    vertices: Float[Array, "3 21"]  # the vertex joints (skinned)


def _pose_blend(km: KeypointModel, feature: Float[Array, "3 3 55"]) -> Float[Array, "3 21"]:
    """The vertex joints' pose blend shapes for a pose feature ``(R_j - I)`` (or its derivative)."""
    return (feature[:, :, 1:].reshape(-1) @ km.posedirs).reshape(3, NUM_VERTEX_JOINTS)


@jax.jit  # traced once, reused by each of the fit's many call sites
def _pose(km: KeypointModel, pose_rotvecs, betas) -> _Posed:
    """The skinning of `smplx_jax.forward_joints`, for the skeleton and the vertex joints only."""
    body = km.body
    glob, p = smplx_jax.posed_skeleton(body, params_of(pose_rotvecs, betas, body.num_expression))
    glob, p = jnp.transpose(glob, (1, 2, 0)), p.T
    rel = jnp.transpose(smplx_jax.rotations.rotvec_to_rotmat(pose_rotvecs), (1, 2, 0))
    rest_joints = (body.joint_template + body.joint_shapedirs[..., : betas.shape[0]] @ betas).T  # (3, 55)
    rest = body.sparse_template_cm + jnp.einsum("b,cbv->cv", betas, km.vertex_shapedirs)
    if km.pose_correctives:
        rest = rest + _pose_blend(km, rel - jnp.eye(3, dtype=rel.dtype)[:, :, None])
    joints, weights = body.sparse_skin_joints, body.sparse_skin_weights  # (I, 21)
    carried = mat3.matvec(glob[:, :, joints], rest[:, None, :] - rest_joints[:, joints]) + p[:, joints]
    return _Posed(glob, p, rel, carried, jnp.sum(weights * carried, axis=1))


def _gather(skeleton_part, vertex_part, index):
    """Columns ``index`` of the 76 joints: skeleton joints from ``(..., 55)``, vertex joints from ``(..., 21)``."""
    return jnp.concatenate([skeleton_part, vertex_part], axis=-1)[..., index]


@jax.custom_jvp
def keypoints_cm(km: KeypointModel, pose_rotvecs: Float[Array, "55 3"], betas: Float[Array, "B"]
                 ) -> Float[Array, "3 K"]:
    """The ``K`` keypoints of one body, coordinate-major (no translation). Differentiable in pose and shape
    (to any order); the model is a constant."""
    posed = _pose(km, pose_rotvecs, betas)
    return _gather(posed.p, posed.vertices, km.index)


class Linearization(NamedTuple):
    """The keypoint map at one point, coordinate-major."""

    x: Float[Array, "3 K"]  # the keypoints
    p: Float[Array, "3 55"]  # joint positions
    a: Float[Array, "3 3 55"]  # world increment per unit dtheta: G_parent J_l(theta)
    jb: Float[Array, "B 3*K"]  # dx/dbetas, row b holds all x then all y then all z
    offsets: Float[Array, "3 P"]  # W_i (y_i - x_v) of the blended pairs (the blended skinning's correction)
    jl: Float[Array, "3 3 55"]  # J_l(theta), the local increment per unit dtheta (pose blend shapes)
    rel: Float[Array, "3 3 55"]
    blend: Float[Array, "3 3 21"]  # skinning-weighted global rotation of each vertex joint
    g_parent: Float[Array, "3 3 55"]  # each joint's parent's global rotation (the identity for the root)


def linearize(km: KeypointModel, pose_rotvecs: Float[Array, "55 3"], betas: Float[Array, "B"]) -> Linearization:
    """The keypoint map of ``km`` at ``pose_rotvecs`` and ``betas``: the keypoints and what their analytic
    Jacobian needs (`Linearization`; used by `jvp`, `vjp` and `pose_jacobian`)."""
    body = km.body
    posed = _pose(km, pose_rotvecs, betas)
    g, p = posed.glob, posed.p
    parents = np.asarray(body.parents)
    g_parent = jnp.concatenate([jnp.eye(3, dtype=g.dtype)[:, :, None], g[:, :, parents[1:]]], axis=2)
    jl = jnp.transpose(mat3.left_jacobian(pose_rotvecs), (1, 2, 0))
    sd = km.joint_shapedirs  # (3, B, 55)
    nb = sd.shape[1]
    bone_sd = mat3.matvec(g_parent, sd - km.parent_shapedirs).at[:, :, 0].set(sd[:, :, 0])  # in the world
    joint_sd = (bone_sd.reshape(3 * nb, 55) @ km.ancestors).reshape(3, nb, 55)  # d(joint position)/d(betas)
    blend = (g.reshape(9, 55) @ km.vertex_skin.T).reshape(3, 3, -1)  # (3, 3, 21)
    vertex_sd = (((joint_sd - mat3.matvec(g, sd)).reshape(3 * nb, 55) @ km.vertex_skin.T).reshape(3, nb, -1)
                 + mat3.matvec(blend, km.vertex_shapedirs))  # (3, B, 21)
    jb = _gather(joint_sd, vertex_sd, km.index)  # (3, B, K)
    return Linearization(_gather(p, posed.vertices, km.index), p, mat3.matmul(g_parent, jl),
                         jnp.transpose(jb, (1, 0, 2)).reshape(nb, -1),
                         _blended_offsets(km, posed), jl, posed.rel, blend, g_parent)


def _blended_offsets(km: KeypointModel, posed: _Posed) -> Float[Array, "3 P"]:
    i, v = km.blended
    return km.body.sparse_skin_weights[i, v] * (posed.carried[:, i, v] - posed.vertices[:, v])


def in_tangent(lin: Linearization) -> Linearization:
    """The same map with the pose moved by local increments ``R_j <- exp(dphi_j) R_j`` (in the parent's frame)
    instead of ``dtheta``: `jvp`, `vjp` and `pose_jacobian` of the result take and give ``dphi``."""
    eye = jnp.broadcast_to(jnp.eye(3, dtype=lin.a.dtype)[:, :, None], lin.a.shape)
    return lin._replace(a=lin.g_parent, jl=eye)


def jvp(km: KeypointModel, lin: Linearization, dpose: Float[Array, "55 3"], dbetas: Float[Array, "B"], *,
        exact: bool = True) -> Float[Array, "3 K"]:
    """``J (dpose, dbetas)``: the keypoints' first-order motion. ``exact=False`` leaves out the blended skinning
    of vertex joints and the pose blend shapes (millimetres; the rest is one GEMM each way per batch)."""
    omega = mat3.matvec(lin.a, dpose.T)  # world-frame rotation increments (3, 55)
    dx = (mat3.cross(omega @ km.reach.T, lin.x) - mat3.cross(omega, lin.p) @ km.reach.T
          + (dbetas @ lin.jb).reshape(3, -1))
    if exact and km.blended[0]:  # sum_i (Omega_i - Omega_0) x W_i (y_i - x) over each vertex joint's influences
        dx = dx + mat3.cross(omega @ km.blended_reach, lin.offsets) @ km.blended_select
    if exact and km.pose_correctives:
        phi = mat3.matvec(lin.jl, dpose.T)  # local increments; dR_j = [phi_j]x R_j, column by column
        d_rel = jnp.stack([mat3.cross(phi, lin.rel[:, c]) for c in range(3)], axis=1)  # (3, 3, 55)
        dx = dx + mat3.matvec(lin.blend, _pose_blend(km, d_rel)) @ km.vertex_select
    return dx


def pose_jacobian(km: KeypointModel, lin: Linearization) -> Float[Array, "3 K 55 3"]:
    """``d keypoint / d pose_rotvecs`` as a dense array: `jvp` with ``exact=False`` of each axis-angle component,
    ``reach[k, j] * (a_j e_b) x (x_k - p_j)``."""
    arm = lin.x[:, :, None] - lin.p[:, None, :]  # (3, K, 55)
    return jnp.stack([mat3.cross(jnp.broadcast_to(lin.a[:, b, None, :], arm.shape), arm) for b in range(3)],
                     axis=-1) * km.reach[None, :, :, None]


def vjp(km: KeypointModel, lin: Linearization, cotangent: Float[Array, "3 K"], *, exact: bool = True):
    """``J^T cotangent``: ``(dpose (55, 3), dbetas (B,))``, the transpose of `jvp`."""
    c = cotangent
    ct_omega = mat3.cross(lin.x, c) @ km.reach - mat3.cross(lin.p, c @ km.reach)
    if exact and km.blended[0]:
        ct_omega = ct_omega + mat3.cross(lin.offsets, c @ km.blended_select.T) @ km.blended_reach.T
    dpose = mat3.matvec_t(lin.a, ct_omega)
    if exact and km.pose_correctives:
        ct_feature = (mat3.matvec_t(lin.blend, c @ km.vertex_select.T).reshape(-1) @ km.posedirs.T).reshape(3, 3, -1)
        ct_phi = sum(mat3.cross(lin.rel[:, col, 1:], ct_feature[:, col]) for col in range(3))
        dpose = dpose + jnp.concatenate([jnp.zeros_like(dpose[:, :1]), mat3.matvec_t(lin.jl[:, :, 1:], ct_phi)], 1)
    return dpose.T, lin.jb @ c.reshape(-1)


@keypoints_cm.defjvp
def _keypoints_jvp(primals, tangents):
    km, pose_rotvecs, betas = primals
    _, dpose, dbetas = tangents
    lin = linearize(km, pose_rotvecs, betas)
    return lin.x, jvp(km, lin, dpose, dbetas)
