"""Headless software rendering of meshes in numpy: vectorised rasterisation, flat Lambert shading, no OpenGL.

Points are in the image's camera frame: x right and y down in pixels, z away from the viewer (any unit).
"""

import cv2
import numpy as np

from smplx_jax.geometry import face_normals

_LIGHT = np.array([-0.35, -0.45, -0.82], np.float32)  # towards the light: up-left-front
_LIGHT /= np.linalg.norm(_LIGHT)


def rasterize(points: np.ndarray, faces: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """(height, width) index of the triangle seen at each pixel centre, -1 where none.

    Front faces only (counter-clockwise seen from outside), drawn far to near by mean depth: the painter's
    algorithm, evaluated for all covered pixels at once.
    """
    width, height = size
    tri = points.astype(np.float32)[faces]
    x, y = tri[:, :, 0] - 0.5, tri[:, :, 1] - 0.5  # (F, 3) each; pixel centres at integer coordinates
    ax, ay, bx, by = x[:, 1] - x[:, 0], y[:, 1] - y[:, 0], x[:, 2] - x[:, 0], y[:, 2] - y[:, 0]
    area = ax * by - ay * bx  # < 0: facing the viewer (y down)
    x0 = np.maximum(np.ceil(np.minimum(np.minimum(x[:, 0], x[:, 1]), x[:, 2])), 0).astype(np.int32)
    y0 = np.maximum(np.ceil(np.minimum(np.minimum(y[:, 0], y[:, 1]), y[:, 2])), 0).astype(np.int32)
    x1 = np.minimum(np.floor(np.maximum(np.maximum(x[:, 0], x[:, 1]), x[:, 2])), width - 1).astype(np.int32)
    y1 = np.minimum(np.floor(np.maximum(np.maximum(y[:, 0], y[:, 1]), y[:, 2])), height - 1).astype(np.int32)
    keep = np.flatnonzero((area < 0) & (x1 >= x0) & (y1 >= y0))
    keep = keep[np.argsort(-(tri[keep, 0, 2] + tri[keep, 1, 2] + tri[keep, 2, 2]), kind="stable")]
    wide = x1[keep] - x0[keep] + 1
    count = wide * (y1[keep] - y0[keep] + 1)
    # one row per candidate pixel of each triangle's bounding box, in drawing order (1-D gathers only: fast)
    k = np.repeat(np.arange(len(keep), dtype=np.int32), count)
    local = np.arange(len(k), dtype=np.int32) - (np.cumsum(count, dtype=np.int32) - count)[k]
    w = wide[k]
    f = keep[k]
    px, py = x0[f] + local % w, y0[f] + local // w
    rx, ry = px - x[f, 0], py - y[f, 0]
    inv = 1.0 / area[f]
    w1 = (rx * by[f] - ry * bx[f]) * inv
    w2 = (ry * ax[f] - rx * ay[f]) * inv
    inside = (w1 >= 0) & (w2 >= 0) & (w1 + w2 <= 1)
    ids = np.full(height * width, -1, np.int32)
    ids[(py * width + px)[inside]] = f[inside]  # later (nearer) triangles overwrite
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
    ids = rasterize(points, faces, (image.shape[1], image.shape[0])).ravel()
    covered = np.flatnonzero(ids >= 0)
    seen = ids[covered]
    shade = face_shading(points.astype(np.float32), faces, _LIGHT, 0.3)[seen, None]
    color = np.asarray(color, np.float32)
    out = image.copy()
    pixels = out.reshape(-1, 3)
    mesh = shade * (color[seen] if color.ndim == 2 else color)
    pixels[covered] = np.clip(opacity * mesh + (1 - opacity) * pixels[covered], 0, 255).astype(np.uint8)
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
