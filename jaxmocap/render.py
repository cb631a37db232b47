"""Headless software rendering of meshes in numpy: vectorised rasterisation, flat Lambert shading, no OpenGL.

Points are in the image's camera frame: x right and y down in pixels, z away from the viewer (any unit).
"""

import cv2
import numpy as np

from smplx_jax.geometry import face_normals

_LIGHT = np.array([-0.35, -0.45, -0.82]) / np.linalg.norm([-0.35, -0.45, -0.82])  # towards the light: up-left-front


def rasterize(points: np.ndarray, faces: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(height, width) index of the triangle seen at each pixel centre, -1 where none.

    Front faces only (counter-clockwise seen from outside), drawn far to near by mean depth: the painter's
    algorithm, evaluated for all covered pixels at once.
    """
    width, height = size
    tri = points[faces].astype(np.float32)
    xy = tri[:, :, :2] - 0.5  # pixel centres at integer coordinates
    e1, e2 = xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]
    area = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]  # < 0: facing the viewer (y down)
    lo = np.maximum(np.ceil(xy.min(axis=1)), 0).astype(np.int32)
    hi = np.minimum(np.floor(xy.max(axis=1)), [width - 1, height - 1]).astype(np.int32)
    keep = np.flatnonzero((area < 0) & np.all(hi >= lo, axis=1))
    keep = keep[np.argsort(-tri[keep, :, 2].mean(axis=1), kind="stable")]
    extent = hi[keep] - lo[keep] + 1
    count = extent[:, 0] * extent[:, 1]
    # one row per candidate pixel, gathered from per-triangle tables (in drawing order)
    k = np.repeat(np.arange(len(keep), dtype=np.int32), count)
    ints = np.stack([np.cumsum(count) - count, extent[:, 0], lo[keep, 0], lo[keep, 1]], axis=1).astype(np.int32)[k]
    inv = 1.0 / area[keep, None]
    floats = np.concatenate([xy[keep, 0], e1[keep] * inv, e2[keep] * inv], axis=1)[k]
    local = np.arange(len(k), dtype=np.int32) - ints[:, 0]
    px, py = ints[:, 2] + local % ints[:, 1], ints[:, 3] + local // ints[:, 1]
    rx, ry = px - floats[:, 0], py - floats[:, 1]
    w1 = rx * floats[:, 5] - ry * floats[:, 4]
    w2 = ry * floats[:, 2] - rx * floats[:, 3]
    inside = (w1 >= 0) & (w2 >= 0) & (w1 + w2 <= 1)
    ids = np.full(height * width, -1, np.int32)
    ids[(py * width + px)[inside]] = keep[k[inside]]  # later (nearer) triangles overwrite
    return ids.reshape(height, width)


def face_shading(points: np.ndarray, faces: np.ndarray, light: np.ndarray, ambient: float) -> np.ndarray:
    """(F,) Lambertian brightness in [ambient, 1] of each face (counter-clockwise seen from outside), lit from the
    unit direction ``light`` (towards the light, in the frame of ``points``)."""
    normals = face_normals(points, faces)
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    return ambient + (1 - ambient) * np.clip(normals @ light, 0.0, 1.0)


def draw_mesh(image: np.ndarray, points: np.ndarray, faces: np.ndarray, color=(150, 175, 215),
              opacity: float = 1.0) -> np.ndarray:
    """A copy of a BGR ``image`` with the mesh drawn over it, flat-shaded by a light at the upper left front.

    ``points (V, 3)``: pixel x, pixel y, depth; ``faces (F, 3)`` counter-clockwise seen from outside; ``color``
    one BGR colour, or one per face ``(F, 3)`` (several meshes drawn as one, each hiding the others).
    """
    ids = rasterize(points, faces, (image.shape[1], image.shape[0]))
    shade = face_shading(points, faces, _LIGHT, 0.3)
    covered = ids >= 0
    out = image.copy()
    color = np.asarray(color, np.float64)
    mesh = shade[ids[covered], None] * (color[ids[covered]] if color.ndim == 2 else color)
    out[covered] = np.clip(opacity * mesh + (1 - opacity) * out[covered], 0, 255).astype(np.uint8)
    return out


def view_points(vertices: np.ndarray, size: tuple[int, int], *, yaw_deg: float = 0.0, pitch_deg: float = 0.0,
                focus=None, margin: float = 0.08) -> np.ndarray:
    """Camera-frame points of a y-up, +z-facing mesh seen from the front after turning it by ``yaw_deg`` about
    the vertical axis and ``pitch_deg`` about the horizontal one, scaled so that the ``focus`` vertices (a mask
    or ids; default all) fill a ``(width, height)`` image."""
    yaw, pitch = np.deg2rad(yaw_deg), np.deg2rad(pitch_deg)
    turn = np.array([[np.cos(yaw), 0, np.sin(yaw)], [0, 1, 0], [-np.sin(yaw), 0, np.cos(yaw)]])
    tilt = np.array([[1, 0, 0], [0, np.cos(pitch), -np.sin(pitch)], [0, np.sin(pitch), np.cos(pitch)]])
    camera = vertices @ (tilt @ turn).T * np.array([1.0, -1.0, -1.0])  # y down, z away from the viewer
    fit = camera if focus is None else camera[focus]
    lo, hi = fit[:, :2].min(axis=0), fit[:, :2].max(axis=0)
    width, height = size
    scale = (1 - 2 * margin) * min(width / (hi[0] - lo[0]), height / (hi[1] - lo[1]))
    xy = (camera[:, :2] - (lo + hi) / 2) * scale + np.array([width / 2, height / 2])
    return np.concatenate([xy, camera[:, 2:] * scale], axis=1)


def label(image: np.ndarray, text: str) -> np.ndarray:
    """The image with a caption in its top-left corner (in place)."""
    cv2.putText(image, text, (10, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (40, 40, 40), 1, cv2.LINE_AA)
    return image
