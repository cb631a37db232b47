"""The overlay video: each frame with the posed mesh drawn over it, beside a side view of the same mesh."""

import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from jaxmocap.render import draw_mesh
from smplx_jax.rotations import rotvec_to_rotmat

_TURN = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # a quarter turn about the image's y axis


def mesh_over_frame(frame: np.ndarray, vertices: np.ndarray, faces: np.ndarray, camera_scale: float,
                    camera_trans: np.ndarray, scale: float = 1.0, focal_length: float | None = None,
                    principal_point: np.ndarray | None = None) -> np.ndarray:
    """The frame (resized by ``scale``) with the mesh drawn where the camera puts it: the pinhole of
    ``focal_length`` and ``principal_point`` when given, else the weak-perspective one.

    ``vertices (V, 3)``: the posed model (``transl`` included) in the image-aligned frame of motion.npz."""
    image = cv2.resize(frame, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) if scale != 1 else frame
    if focal_length is None:
        points = np.concatenate([vertices[:, :2] * camera_scale + camera_trans, vertices[:, 2:] * camera_scale], 1)
    else:  # depth in pixels at the body's distance, as the weak-perspective case has it
        depth = vertices[:, 2:]
        points = np.concatenate([focal_length * vertices[:, :2] / depth + principal_point,
                                 depth * focal_length / np.median(depth)], axis=1)
    return draw_mesh(image, points * scale, faces, opacity=0.75)


def upright(up: np.ndarray) -> np.ndarray:
    """The rotation (3, 3) taking the camera-frame direction ``up`` to the image's up ``(0, -1, 0)``."""
    a, b = up / np.linalg.norm(up), np.array([0.0, -1.0, 0.0])
    v, c = np.cross(a, b), float(a @ b)
    if c < -1 + 1e-9:  # upside down: half a turn about the image's x axis
        return np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


def body_up(global_orient: np.ndarray) -> np.ndarray:
    """The mean direction of the bodies' up axis (SMPL-X's y) in the camera frame, of ``(T, 3)`` orientations:
    the vertical of a person who mostly stands."""
    return np.asarray(rotvec_to_rotmat(np.asarray(global_orient, np.float32)))[:, :, 1].mean(0)


def side_view(vertices: np.ndarray, faces: np.ndarray, size: tuple[int, int], pixels_per_metre: float,
              centre: np.ndarray, detail: float = 0.5, up: np.ndarray | None = None) -> np.ndarray:
    """The mesh seen from the person's side (the image's x axis turned into depth), stood up on ``up`` (the
    camera-frame vertical, default the image's), on a plain background; rendered at ``detail`` times the size
    and scaled up (rasterising cost grows with the pixels covered)."""
    width, height = size
    small = (max(1, round(width * detail)), max(1, round(height * detail)))
    level = np.eye(3) if up is None else upright(up)
    turned = (vertices - centre) @ (_TURN @ level).T * (pixels_per_metre * detail)
    points = np.concatenate([turned[:, :2] + [small[0] / 2, small[1] / 2], turned[:, 2:]], axis=1)
    image = draw_mesh(np.full((small[1], small[0], 3), 235, np.uint8), points, faces)
    return cv2.resize(image, size, interpolation=cv2.INTER_LINEAR)


class OverlayWriter:
    """Writes the side-by-side overlay video (``mp4v``), the frames scaled so that the height is at most
    ``max_height``; the side view keeps the first frame's scale and follows the body's centre. Frames are
    composed in parallel threads (the rasteriser's numpy work releases the GIL)."""

    def __init__(self, path: Path, frame_size: tuple[int, int], fps: float, max_height: int = 960,
                 lens: tuple = (None, None), up: np.ndarray | None = None):
        width, height = frame_size
        self.lens = lens  # (focal_length, principal_point) of a pinhole camera, or (None, None)
        self.up = up  # the side view's vertical in the camera frame (`body_up`)
        self.scale = min(1.0, max_height / height)
        self.panel = (int(round(width * self.scale)), int(round(height * self.scale)))
        self.path = Path(path)
        self.writer = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*"mp4v"), fps,
                                      (2 * self.panel[0], self.panel[1]))
        if not self.writer.isOpened():
            raise OSError(f"cannot write the overlay video {self.path}")
        self.pixels_per_metre = None
        self.pool = ThreadPoolExecutor(os.cpu_count() or 1)

    def compose(self, frame, vertices=None, faces=None, camera_scale=None, camera_trans=None) -> np.ndarray:
        """One output image; without vertices (no person) the frame as it is beside an empty side view."""
        if vertices is None:
            left = cv2.resize(frame, self.panel, interpolation=cv2.INTER_AREA)
            right = np.full((self.panel[1], self.panel[0], 3), 235, np.uint8)
        else:
            left = mesh_over_frame(frame, vertices, faces, camera_scale, camera_trans, self.scale, *self.lens)
            if left.shape[1::-1] != self.panel:
                left = cv2.resize(left, self.panel)
            lo, hi = vertices.min(axis=0), vertices.max(axis=0)
            if self.pixels_per_metre is None:
                self.pixels_per_metre = float(0.75 * self.panel[1] / (hi - lo).max())
            right = side_view(vertices, faces, self.panel, self.pixels_per_metre, (lo + hi) / 2, up=self.up)
        return np.concatenate([left, right], axis=1)

    def write(self, *frames) -> None:
        """Frames in order, each an argument tuple of `compose`, composed in parallel threads."""
        first = next((f for f in frames if len(f) > 1 and f[1] is not None), None)
        if first is not None and self.pixels_per_metre is None:
            self.compose(*first)  # fixes the side view's scale before the threads share it
        for image in self.pool.map(lambda args: self.compose(*args), frames):
            self.writer.write(image)

    def close(self) -> None:
        self.pool.shutdown()
        self.writer.release()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
