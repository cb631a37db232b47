"""The overlay video: each frame with the posed meshes of its people drawn over it, beside a side view of them."""

import os
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from jaxmocap.render import draw_mesh
from smplx_jax.rotations import rotvec_to_rotmat

GROUND = (200, 205, 200)  # the side view's floor
_TURN = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # a quarter turn about the image's y axis


COLOURS = ((150, 175, 215), (120, 200, 140), (215, 160, 120), (110, 150, 235), (200, 130, 200), (120, 210, 220))


def person_colour(person_id: int) -> tuple[int, int, int]:
    """The BGR colour a person is drawn in, by identity."""
    return COLOURS[person_id % len(COLOURS)]


@dataclass(frozen=True)
class Posed:
    """One person (or hand) in one frame: identity, posed vertices ``(V, 3)`` (``transl`` included, the
    image-aligned frame of motion.npz) and the weak-perspective camera; ``faces`` of its own mesh (default: those
    of the drawing's model) and the ``label`` drawn above it (default: the identity)."""

    person_id: int
    vertices: np.ndarray
    camera_scale: float
    camera_trans: np.ndarray
    faces: np.ndarray | None = None
    label: str | None = None


def mesh_pixels(vertices: np.ndarray, camera_scale: float, camera_trans: np.ndarray,
                focal_length: float | None = None, principal_point: np.ndarray | None = None,
                depth_unit: float | None = None) -> np.ndarray:
    """``(V, 3)`` pixel x, y and a depth of the vertices where the camera puts them: the pinhole of
    ``focal_length`` and ``principal_point`` when given (depth in pixels at ``depth_unit`` metres, default the
    mesh's median depth), else the weak-perspective one."""
    if focal_length is None:
        return np.concatenate([vertices[:, :2] * camera_scale + camera_trans, vertices[:, 2:] * camera_scale], 1)
    depth = vertices[:, 2:]
    unit = np.median(depth) if depth_unit is None else depth_unit
    return np.concatenate([focal_length * vertices[:, :2] / depth + principal_point, depth * focal_length / unit], 1)


def mesh_over_frame(frame: np.ndarray, vertices: np.ndarray, faces: np.ndarray, camera_scale: float,
                    camera_trans: np.ndarray, scale: float = 1.0, focal_length: float | None = None,
                    principal_point: np.ndarray | None = None) -> np.ndarray:
    """The frame (resized by ``scale``) with the mesh drawn where the camera puts it (`mesh_pixels`)."""
    return people_over_frame(frame, [Posed(0, vertices, camera_scale, camera_trans)], faces, scale, focal_length,
                             principal_point, labels=False)


def people_over_frame(frame: np.ndarray, people: list[Posed], faces: np.ndarray, scale: float = 1.0,
                      focal_length: float | None = None, principal_point: np.ndarray | None = None,
                      labels: bool = True) -> np.ndarray:
    """The frame (resized by ``scale``) with each person's mesh drawn in their colour, nearer ones hiding farther
    ones, and (``labels``) their identity above their head."""
    image = shrunk(frame, scale) if scale != 1 else frame
    if not people:
        return image.copy()
    unit = float(np.median(np.concatenate([p.vertices[:, 2] for p in people])))
    points = [mesh_pixels(p.vertices, p.camera_scale, p.camera_trans, focal_length, principal_point, unit) * scale
              for p in people]
    drawn = draw_mesh(image, *_joined(points, people, faces), opacity=0.75)
    for person, xyz in zip(people if labels else (), points):
        top = xyz[np.argmin(xyz[:, 1]), :2]
        label = str(person.person_id) if person.label is None else person.label
        cv2.putText(drawn, label, (int(top[0]) - 10, int(top[1]) - 12), cv2.FONT_HERSHEY_SIMPLEX,
                    1.2, person_colour(person.person_id), 3, cv2.LINE_AA)
    return drawn


def shrunk(frame: np.ndarray, scale: float) -> np.ndarray:
    """The frame resized by ``scale``, averaged over pixel areas; far below half size first thinned to twice the
    size by nearest neighbours (OpenCV's area resize is ~15 times slower at a factor that does not divide)."""
    if scale < 0.5:
        twice = (round(frame.shape[1] * 2 * scale), round(frame.shape[0] * 2 * scale))
        frame, scale = cv2.resize(frame, twice, interpolation=cv2.INTER_NEAREST), 0.5
    return cv2.resize(frame, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)


def _joined(points: list[np.ndarray], people: list[Posed], faces: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The people's meshes as one: stacked points, offset faces (each one's own, else ``faces``) and a colour per
    face (each one's identity's)."""
    own = [faces if p.faces is None else p.faces for p in people]
    offsets = np.cumsum([0] + [len(x) for x in points[:-1]])
    joined_faces = np.concatenate([f + k for f, k in zip(own, offsets)])
    colours = np.concatenate([np.repeat([person_colour(p.person_id)], len(f), axis=0) for p, f in zip(people, own)])
    return np.concatenate(points), joined_faces, colours.astype(np.float64)


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


def side_view(people: list[Posed], faces: np.ndarray, size: tuple[int, int], pixels_per_metre: float,
              centre: np.ndarray, detail: float = 0.5, up: np.ndarray | None = None,
              floor: np.ndarray | None = None) -> np.ndarray:
    """The people's meshes seen from the side (the image's x axis turned into depth), stood up on ``up`` (the
    camera-frame vertical, default the image's), on a plain background; rendered at ``detail`` times the size
    and scaled up (rasterising cost grows with the pixels covered). ``floor``: motion.npz's ``(nx, ny, nz, d)``
    in the camera's frame, whose normal is then the view's up: drawn as the ground under the people."""
    width, height = size
    small = (max(1, round(width * detail)), max(1, round(height * detail)))
    up = up if floor is None else np.asarray(floor[:3], np.float64)
    level = np.eye(3) if up is None else upright(up)

    def placed(points: np.ndarray) -> np.ndarray:  # camera frame -> the small image's pixels and depth
        turned = (points - centre) @ (_TURN @ level).T * (pixels_per_metre * detail)
        return np.concatenate([turned[:, :2] + [small[0] / 2, small[1] / 2], turned[:, 2:]], axis=1)

    points = [placed(person.vertices) for person in people]
    background = np.full((small[1], small[0], 3), 235, np.uint8)
    if floor is not None:  # the plane seen edge on: the rows below its line
        row = placed(-float(floor[3]) * up[None] / np.linalg.norm(up))[0, 1]
        background[int(np.clip(np.ceil(row), 0, small[1])):] = GROUND
    image = draw_mesh(background, *_joined(points, people, faces)) if people else background
    return cv2.resize(image, size, interpolation=cv2.INTER_LINEAR)


class OverlayWriter:
    """Writes the side-by-side overlay video (``mp4v``) of the people in each frame, the frames scaled so that the
    height is at most ``max_height``; the side view keeps the first frame's scale (a body and the people's
    ``spread``) and follows the people's centre.
    Frames are composed in parallel threads (the rasteriser's numpy work releases the GIL)."""

    def __init__(self, path: Path, frame_size: tuple[int, int], fps: float, faces: np.ndarray,
                 max_height: int = 960, lens: tuple = (None, None), up: np.ndarray | None = None,
                 spread: float = 0.0):
        width, height = frame_size
        self.spread = spread  # metres between the people, at most: the side view's scale leaves room for it
        self.faces = np.asarray(faces)
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

    def compose(self, frame: np.ndarray, people: list[Posed] = (), floor: np.ndarray | None = None) -> np.ndarray:
        """One output image: the frame with the people drawn over it beside the side view (empty without
        anyone), the ``floor`` under them (`side_view`)."""
        left = people_over_frame(frame, list(people), self.faces, self.scale, *self.lens)
        if left.shape[1::-1] != self.panel:
            left = cv2.resize(left, self.panel, interpolation=cv2.INTER_AREA)
        if not people:
            return np.concatenate([left, np.full((self.panel[1], self.panel[0], 3), 235, np.uint8)], axis=1)
        everyone = np.concatenate([p.vertices for p in people])
        lo, hi = everyone.min(axis=0), everyone.max(axis=0)
        if self.pixels_per_metre is None:
            tallest = max(float((p.vertices.max(axis=0) - p.vertices.min(axis=0)).max()) for p in people)
            self.pixels_per_metre = 0.75 * self.panel[1] / (tallest + self.spread)
        right = side_view(list(people), self.faces, self.panel, self.pixels_per_metre, (lo + hi) / 2, up=self.up,
                          floor=floor)
        return np.concatenate([left, right], axis=1)

    def write(self, *frames: tuple) -> None:
        """Frames in order, each ``(frame, people)`` or ``(frame, people, floor)`` (`compose`), composed in parallel
        threads."""
        first = next((f for f in frames if len(f[1])), None)
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
