"""Triangle-mesh geometry in numpy, shared by the default model's generator, the glTF export and the renderer.

The default model's generator (``smplx_jax/_default``) calls these, so `smplx_jax.default_model.generator_id`
hashes this file too: a change here is a new generator.
"""

import numpy as np


def face_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) normals of the triangles, not normalised: twice each triangle's area long, pointing to the side
    from which its vertices run counter-clockwise."""
    tri = vertices[faces]
    return np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(V, 3) vertex normals: the area-weighted sum of the normals of the triangles around each vertex, divided
    by its length plus 1e-12 (zero for a vertex no triangle uses; a vertex whose triangles are tiny, ~1e-6 m²
    in all, comes out shorter than unit by ~1e-12 / area: the default model's generator depends on these
    exact values)."""
    by_face = face_normals(vertices, faces)
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, faces[:, k], by_face)
    return normals / (np.linalg.norm(normals, axis=1, keepdims=True) + 1e-12)
