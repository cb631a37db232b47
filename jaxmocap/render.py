"""Headless software rendering of meshes with OpenCV: painter's algorithm, Lambert shading, no OpenGL.

Points are in the image's camera frame: x right and y down in pixels, z away from the viewer (any unit).
"""

import cv2
import numpy as np

_LIGHT = np.array([-0.35, -0.45, -0.82]) / np.linalg.norm([-0.35, -0.45, -0.82])  # towards the light: up-left-front


def draw_mesh(image: np.ndarray, points: np.ndarray, faces: np.ndarray, color=(150, 175, 215)) -> np.ndarray:
    """A copy of a BGR ``image`` with the mesh drawn over it.

    ``points (V, 3)``: pixel x, pixel y, depth; ``faces (F, 3)`` counter-clockwise seen from outside.
    """
    out = image.copy()
    tri = points[faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    lengths = np.linalg.norm(normals, axis=1)
    normals = normals / np.where(lengths > 0, lengths, 1.0)[:, None]
    keep = (normals[:, 2] < 0) & (lengths > 0)  # facing the viewer
    order = np.argsort(-tri[keep, :, 2].mean(axis=1), kind="stable")  # far to near
    shade = 0.3 + 0.7 * np.clip(normals[keep][order] @ _LIGHT, 0.0, 1.0)
    polygons = np.round(tri[keep][order][:, :, :2] * 16).astype(np.int32)  # 4 bits of sub-pixel precision
    colors = np.asarray(color, np.float64)[None] * shade[:, None]
    for polygon, c in zip(polygons, colors):
        cv2.fillConvexPoly(out, polygon, c.tolist(), lineType=cv2.LINE_AA, shift=4)
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
