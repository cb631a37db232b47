"""The overlay video: each frame with the posed mesh drawn over it, beside a side view of the same mesh."""

from pathlib import Path

import cv2
import numpy as np

from jaxmocap.render import draw_mesh

_TURN = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # a quarter turn about the image's y axis


def mesh_over_frame(frame: np.ndarray, vertices: np.ndarray, faces: np.ndarray, camera_scale: float,
                    camera_trans: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """The frame (resized by ``scale``) with the mesh drawn where the weak-perspective camera puts it.

    ``vertices (V, 3)``: the posed model (``transl`` included) in the image-aligned frame of motion.npz."""
    image = cv2.resize(frame, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA) if scale != 1 else frame
    points = np.concatenate([vertices[:, :2] * camera_scale + camera_trans, vertices[:, 2:] * camera_scale], axis=1)
    return draw_mesh(image, points * scale, faces, opacity=0.75)


def side_view(vertices: np.ndarray, faces: np.ndarray, size: tuple[int, int], pixels_per_metre: float,
              centre: np.ndarray) -> np.ndarray:
    """The mesh seen from the person's side (the image's x axis turned into depth), on a plain background."""
    width, height = size
    turned = (vertices - centre) @ _TURN.T
    points = np.concatenate([turned[:, :2] * pixels_per_metre + [width / 2, height / 2],
                             turned[:, 2:] * pixels_per_metre], axis=1)
    return draw_mesh(np.full((height, width, 3), 235, np.uint8), points, faces)


class OverlayWriter:
    """Writes the side-by-side overlay video (``mp4v``), the frames scaled so that the height is at most
    ``max_height``; the side view keeps the first frame's scale and follows the body's centre."""

    def __init__(self, path: Path, frame_size: tuple[int, int], fps: float, max_height: int = 960):
        width, height = frame_size
        self.scale = min(1.0, max_height / height)
        self.panel = (int(round(width * self.scale)), int(round(height * self.scale)))
        self.path = Path(path)
        self.writer = cv2.VideoWriter(str(self.path), cv2.VideoWriter_fourcc(*"mp4v"), fps,
                                      (2 * self.panel[0], self.panel[1]))
        if not self.writer.isOpened():
            raise OSError(f"cannot write the overlay video {self.path}")
        self.pixels_per_metre = None

    def write(self, frame, vertices=None, faces=None, camera_scale=None, camera_trans=None) -> None:
        """One frame; without vertices (no person) the frame is shown as it is beside an empty side view."""
        if vertices is None:
            left = cv2.resize(frame, self.panel, interpolation=cv2.INTER_AREA)
            right = np.full((self.panel[1], self.panel[0], 3), 235, np.uint8)
        else:
            left = cv2.resize(mesh_over_frame(frame, vertices, faces, camera_scale, camera_trans, self.scale),
                              self.panel)
            lo, hi = vertices.min(axis=0), vertices.max(axis=0)
            if self.pixels_per_metre is None:
                self.pixels_per_metre = 0.75 * self.panel[1] / (hi - lo).max()
            right = side_view(vertices, faces, self.panel, self.pixels_per_metre, (lo + hi) / 2)
        self.writer.write(np.concatenate([left, right], axis=1))

    def close(self) -> None:
        self.writer.release()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
