"""Images for the synthetic datasets: random cluttered backgrounds and flat-shaded meshes seen by a pinhole camera.

Points are in the camera frame (metres, x right, y down, z forward); pixel coordinates put pixel ``(i, j)``'s
centre at ``(j + 0.5, i + 0.5)``, as `jaxmocap.render.rasterize` reads them. Triangles are filled one by one
far to near with ``cv2.fillConvexPoly``: for a mesh of a few thousand faces covering much of the image this is
several times faster than the vectorised `jaxmocap.render.rasterize`, whose cost grows with the covered area.
"""

from typing import NamedTuple

import cv2
import numpy as np
from jaxtyping import Bool, Float, Int, UInt8

from jaxmocap.render import face_shading

# sensor grain: unit Gaussian noise stored as 128 + 16 * noise, cropped at random offsets
_GRAIN = np.clip(128 + 16 * np.random.default_rng(0).normal(0.0, 1.0, (512, 512, 3)), 0, 255).astype(np.uint8)


class PinholeCamera(NamedTuple):
    focal: float  # pixels
    center: Float[np.ndarray, "2"]  # principal point, pixels

    def project(self, points: Float[np.ndarray, "*N 3"]) -> Float[np.ndarray, "*N 2"]:
        return self.focal * points[..., :2] / points[..., 2:] + self.center


def background(rng: np.random.Generator, size: int) -> UInt8[np.ndarray, "S S 3"]:
    """Clutter: a colour gradient with low-frequency colour noise, random shapes and lines, often blurred."""
    cells = int(rng.integers(2, 9))
    ramp = np.linspace(-1.0, 1.0, cells)
    angle = rng.uniform(0, 2 * np.pi)
    t = np.cos(angle) * ramp[None, :, None] + np.sin(angle) * ramp[:, None, None]
    noise = rng.normal(0, rng.uniform(5, 45), (cells, cells, 3))
    coarse = rng.uniform(40, 215, 3) + rng.uniform(-70, 70, 3) * t + noise
    image = cv2.resize(np.clip(coarse, 0, 255).astype(np.uint8), (size, size), interpolation=cv2.INTER_CUBIC)
    for _ in range(rng.integers(2, 12)):
        color = tuple(int(c) for c in rng.integers(0, 256, 3))
        x, y = (int(c) for c in rng.integers(-size // 4, size + size // 4, 2))
        kind = rng.integers(4)
        if kind == 0:
            cv2.circle(image, (x, y), int(rng.integers(4, size // 3)), color, -1, cv2.LINE_AA)
        elif kind == 1:
            w, h = (int(c) for c in rng.integers(4, size // 2, 2))
            cv2.rectangle(image, (x, y), (x + w, y + h), color, -1)
        elif kind == 2:
            x2, y2 = (int(c) for c in rng.integers(0, size, 2))
            cv2.line(image, (x, y), (x2, y2), color, int(rng.integers(1, 8)), cv2.LINE_AA)
        else:
            axes = (int(rng.integers(4, size // 3)), int(rng.integers(4, size // 3)))
            cv2.ellipse(image, (x, y), axes, float(rng.uniform(0, 180)), 0, 360, color, -1, cv2.LINE_AA)
    if rng.random() < 0.6:
        image = cv2.GaussianBlur(image, (0, 0), rng.uniform(0.5, 4.0))
    return image


def camera_effects(rng: np.random.Generator, image: UInt8[np.ndarray, "H W 3"]) -> UInt8[np.ndarray, "H W 3"]:
    """Sometimes a slight blur; always some sensor grain (a random crop of a fixed noise texture)."""
    if rng.random() < 0.5:
        image = cv2.GaussianBlur(image, (0, 0), rng.uniform(0.3, 1.2))
    height, width = image.shape[:2]
    y, x = rng.integers(0, _GRAIN.shape[0] - height + 1), rng.integers(0, _GRAIN.shape[1] - width + 1)
    sigma = rng.uniform(0, 7)
    return cv2.addWeighted(image, 1.0, _GRAIN[y:y + height, x:x + width], sigma / 16, -8 * sigma)


def face_ids(points_px: Float[np.ndarray, "V 3"], faces: Int[np.ndarray, "F 3"], size: tuple[int, int]
             ) -> Int[np.ndarray, "H W"]:
    """(height, width) index of the front face seen at each pixel, -1 where none; painter's algorithm."""
    tri = points_px[faces]
    e1, e2 = tri[:, 1, :2] - tri[:, 0, :2], tri[:, 2, :2] - tri[:, 0, :2]
    front = np.flatnonzero(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0)  # counter-clockwise in y-up terms
    order = front[np.argsort(-tri[front, :, 2].mean(axis=1), kind="stable")]
    fixed = np.round((tri[order, :, :2] - 0.5) * 16).astype(np.int32)  # 4 fractional bits
    ids = np.full((size[1], size[0]), -1, np.int32)
    for face, polygon in zip(order.tolist(), fixed):
        cv2.fillConvexPoly(ids, polygon, face, cv2.LINE_8, 4)
    return ids


def render(
    image: UInt8[np.ndarray, "H W 3"],
    camera: PinholeCamera,
    vertices: Float[np.ndarray, "V 3"],
    faces: Int[np.ndarray, "F 3"],
    face_colors: Float[np.ndarray, "F 3"],
    light: Float[np.ndarray, "3"],
    ambient: float,
) -> tuple[UInt8[np.ndarray, "H W 3"], Bool[np.ndarray, "H W"]]:
    """The mesh (camera frame, faces counter-clockwise seen from outside) over a copy of ``image``, Lambertian
    with ``light`` (unit, camera frame, towards the light) plus ``ambient``; also the mask of covered pixels."""
    points_px = np.concatenate([camera.project(vertices), vertices[:, 2:]], axis=1)
    ids = face_ids(points_px, faces, (image.shape[1], image.shape[0]))
    shade = face_shading(vertices, faces, light, ambient)
    face_rgb = np.clip(shade[:, None] * face_colors, 0, 255).astype(np.uint8)
    covered = ids >= 0
    out = image.copy()
    out[covered] = face_rgb[ids[covered]]
    return out, covered
