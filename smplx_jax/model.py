"""`BodyModel`: an SMPL-X model file as an immutable pytree, with what forward needs precomputed."""

import dataclasses
import functools
from pathlib import Path

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from smplx_jax import constants
from smplx_jax.model_file import read_model_file
from smplx_jax.pytree import pytree_dataclass

SHAPE_SPACE_DIM = 300  # shape columns of a 400-column SMPL-X file; expression follows them


def _static(**kwargs):
    return dataclasses.field(metadata=dict(static=True), **kwargs)


@pytree_dataclass
@dataclasses.dataclass(frozen=True)
class BodyModel:
    """One SMPL-X model. ``S = num_betas + num_expression`` shape components, ``P = 9 * 54`` pose features.

    Per-vertex arrays are coordinate-major (all x, then all y, then all z), so that the matrix products of
    a batch of bodies need no transposes. ``skin_joints``/``skin_weights`` list each vertex's ``I`` most
    influential joints, ``I`` the most nonzero skinning weights any vertex of the file has (4 in the default
    model), so that skinning can gather ``I`` transforms per vertex instead of blending all 55. The ``sparse_*``
    arrays hold the few vertices that the vertex joints and face landmarks read, so that `forward_joints`
    never forms the whole mesh; those are always skinned by gathering, whatever ``I`` (there are ~170).
    """

    template_cm: Float[Array, "3 V"]
    shapedirs_cm: Float[Array, "S 3*V"]  # shape components (S,) @ shapedirs_cm -> (3V,)
    posedirs_cm: Float[Array, "P 3*V"]  # pose feature (P,) @ posedirs_cm -> (3V,)
    weights_t: Float[Array, "J V"]
    skin_joints: Int[Array, "I V"]  # each vertex's joints by decreasing weight
    skin_weights: Float[Array, "I V"]  # their weights; all others are zero
    joint_template: Float[Array, "J 3"]  # J_regressor @ v_template
    joint_shapedirs: Float[Array, "J 3 S"]  # J_regressor @ shapedirs
    faces: Int[Array, "F 3"]
    hand_mean: Float[Array, "2 45"]  # left, right
    hand_components: Float[Array, "2 C 45"]  # left, right; rows are PCA components
    sparse_ids: Int[Array, "K"]  # vertex ids of the sparse vertices
    sparse_template_cm: Float[Array, "3 K"]
    sparse_shapedirs_cm: Float[Array, "S 3*K"]
    sparse_posedirs_cm: Float[Array, "P 3*K"]
    sparse_skin_joints: Int[Array, "I K"]
    sparse_skin_weights: Float[Array, "I K"]
    vertex_joint_slots: Int[Array, "21"]  # vertex joints as indices into the sparse vertices
    landmark_slots: Int[Array, "51 3"]  # landmark triangles as indices into the sparse vertices
    landmark_bary: Float[Array, "51 3"]
    parents: tuple[int, ...] = _static()
    num_betas: int = _static()
    num_expression: int = _static()

    @property
    def num_vertices(self) -> int:
        return self.template_cm.shape[1]

    @property
    def v_template(self) -> Float[Array, "V 3"]:
        return self.template_cm.T

    @property
    def weights(self) -> Float[Array, "V J"]:
        return self.weights_t.T


def load_model(path, *, num_betas: int = 10, num_expression: int = 10, dtype=jnp.float32) -> BodyModel:
    """Load an SMPL-X model file (official ``.npz``/``.pkl``, or ours) into a `BodyModel`.

    Shape columns are chosen as the ``smplx`` package does: a 400-column file has 300 shape then 100
    expression columns, a smaller one 10 and 10. Raises `ModelFileError` naming the file and the problem.
    The process keeps the last few models loaded: the same file, unchanged (its size, modification time and inode),
    with the same arguments, gives the same (immutable) `BodyModel` back without reading it again.
    """
    path = Path(path)
    try:
        stat = path.stat()
    except OSError:
        return _load(path, num_betas, num_expression, dtype)  # raises, naming the problem
    return _load_kept(path, stat.st_dev, stat.st_ino, stat.st_size, stat.st_mtime_ns, num_betas, num_expression,
                      jnp.dtype(dtype))


@functools.lru_cache(maxsize=4)  # a float32 model holds ~70 MB, a float64 one ~140 MB
def _load_kept(path: Path, device: int, inode: int, size: int, mtime_ns: int, num_betas: int, num_expression: int,
               dtype) -> BodyModel:
    """`_load`, kept for the same file unchanged (``device`` to ``mtime_ns`` say which) and the same arguments."""
    return _load(path, num_betas, num_expression, dtype)


def _load(path: Path, num_betas: int, num_expression: int, dtype) -> BodyModel:
    arrays = read_model_file(path)
    shape_dim = SHAPE_SPACE_DIM if arrays["shapedirs"].shape[-1] >= 400 else 10
    expression_dim = arrays["shapedirs"].shape[-1] - shape_dim
    for name, value, limit in (("num_betas", num_betas, shape_dim), ("num_expression", num_expression, expression_dim)):
        if not 0 <= value <= limit:
            raise ValueError(f"{name}={value}: the model file {path} has {limit} such components")
    shapedirs = np.concatenate(
        [arrays["shapedirs"][..., :num_betas], arrays["shapedirs"][..., shape_dim:shape_dim + num_expression]], axis=-1)
    return _build(arrays, shapedirs, num_betas, num_expression, dtype)


def device_array(a, dtype) -> Array:
    """The NumPy array ``a`` as a JAX array of ``dtype``, converted by NumPy: JAX would compile a conversion program
    for each shape (and run it alone, even inside a trace, under `jax.ensure_compile_time_eval`)."""
    return jnp.asarray(np.asarray(a, np.dtype(dtype)), dtype)


def _coordinate_major(per_vertex: np.ndarray) -> np.ndarray:
    """(N, 3, ...) per-vertex data to (..., 3N) with column ``c * N + n``."""
    moved = np.moveaxis(per_vertex, (0, 1), (-1, -2))
    return moved.reshape(moved.shape[:-2] + (-1,))


def _build(arrays, shapedirs, num_betas, num_expression, dtype) -> BodyModel:
    v_template = arrays["v_template"]
    j_regressor = arrays["J_regressor"]
    posedirs = arrays["posedirs"]  # (V, 3, P)
    faces = arrays["f"].astype(np.int64)
    lmk_faces = faces[arrays["lmk_faces_idx"].astype(np.int64)]

    # Vertices needed by the vertex joints and landmarks, and their slots among them.
    needed = np.concatenate([np.asarray(constants.VERTEX_JOINT_IDS), lmk_faces.ravel()])
    sparse_ids, slots = np.unique(needed, return_inverse=True)
    num_vertex_joints = len(constants.VERTEX_JOINT_IDS)

    weights = arrays["weights"]
    influences = max(1, int(np.count_nonzero(weights, axis=1).max()))
    skin_joints = np.argsort(-weights, axis=1, kind="stable")[:, :influences]
    skin_weights = np.take_along_axis(weights, skin_joints, axis=1)

    hand_components = np.stack([arrays["hands_componentsl"], arrays["hands_componentsr"]])
    f = functools.partial(device_array, dtype=dtype)
    return BodyModel(
        template_cm=f(v_template.T),
        shapedirs_cm=f(_coordinate_major(shapedirs)),
        posedirs_cm=f(_coordinate_major(posedirs)),
        weights_t=f(weights.T),
        skin_joints=device_array(skin_joints.T, jnp.int32),
        skin_weights=f(skin_weights.T),
        joint_template=f(j_regressor @ v_template),
        joint_shapedirs=f(np.einsum("jv,vcs->jcs", j_regressor, shapedirs)),
        faces=device_array(faces, jnp.int32),
        hand_mean=f(np.stack([arrays["hands_meanl"], arrays["hands_meanr"]])),
        hand_components=f(hand_components),
        sparse_ids=device_array(sparse_ids, jnp.int32),
        sparse_template_cm=f(v_template[sparse_ids].T),
        sparse_shapedirs_cm=f(_coordinate_major(shapedirs[sparse_ids])),
        sparse_posedirs_cm=f(_coordinate_major(posedirs[sparse_ids])),
        sparse_skin_joints=device_array(skin_joints[sparse_ids].T, jnp.int32),
        sparse_skin_weights=f(skin_weights[sparse_ids].T),
        vertex_joint_slots=device_array(slots[:num_vertex_joints], jnp.int32),
        landmark_slots=device_array(slots[num_vertex_joints:].reshape(-1, 3), jnp.int32),
        landmark_bary=f(arrays["lmk_bary_coords"]),
        parents=tuple(int(p) for p in arrays["parents"]),
        num_betas=num_betas,
        num_expression=num_expression,
    )
