"""A random SMPL-X model file with the official shapes, for equivalence tests that need no licensed file."""

import numpy as np

from smplx_jax import constants

PARENTS = np.array([-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15, 20, 25, 26,
                    20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38, 21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50,
                    21, 52, 53])


def random_model_arrays(seed: int = 0, num_vertices: int = 10475, num_faces: int = 20908) -> dict[str, np.ndarray]:
    """Official keys, shapes and dtypes (400 shape columns, 486 pose features); sparse random skinning weights
    (each vertex on 4 joints, one dominant) and a sparse joint regressor, as in real files."""
    rng = np.random.default_rng(seed)
    nj = constants.NUM_JOINTS
    v_template = rng.uniform(-0.8, 0.8, (num_vertices, 3))
    weights = np.zeros((num_vertices, nj))
    for v in range(num_vertices):
        joints = rng.choice(nj, 4, replace=False)
        weights[v, joints] = rng.dirichlet([4.0, 1.0, 1.0, 1.0])
    j_regressor = np.zeros((nj, num_vertices))
    for j in range(nj):
        ids = rng.choice(num_vertices, 12, replace=False)
        j_regressor[j, ids] = rng.dirichlet(np.ones(12))
    components = np.linalg.qr(rng.normal(size=(45, 45)))[0]
    return {
        "v_template": v_template,
        "shapedirs": rng.normal(0, 0.01, (num_vertices, 3, 400)),
        "posedirs": rng.normal(0, 0.01, (num_vertices, 3, 9 * (nj - 1))),
        "J_regressor": j_regressor,
        "weights": weights,
        "kintree_table": np.stack([np.where(PARENTS < 0, 4294967295, PARENTS), np.arange(nj)]).astype(np.int64),
        "f": rng.integers(0, num_vertices, (num_faces, 3)).astype(np.int32),
        "hands_componentsl": components,
        "hands_componentsr": components[::-1].copy(),
        "hands_meanl": rng.normal(0, 0.2, 45),
        "hands_meanr": rng.normal(0, 0.2, 45),
        "lmk_faces_idx": rng.integers(0, num_faces, 51).astype(np.int64),
        "lmk_bary_coords": rng.dirichlet(np.ones(3), 51),
    }
