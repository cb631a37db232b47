"""The scene's vertical direction seen from a static camera: the vanishing direction of the straight edges that
stand upright (door frames, corners of walls, furniture, poles), among the line segments of a few frames (OpenCV's
LSD detector, `Segments`). Through a lens, a segment spans a plane through the camera's centre; segments parallel
to a direction ``d`` have planes that contain it (their unit normals ``l`` have ``l · d = 0``). ``d`` is looked
for near the up direction the body suggests (RANSAC over pairs of edges, scored by the length of those that agree),
then refined by least squares over those (`vertical_direction`); None where too few edges agree.

The direction is as exact as the lens: a focal length 15% off tilts it by some 3 degrees in a camera looking down
by 20 degrees. Where the scene also has level edges (a floor's, a wall's, a table's), its focal length is the one
under which they lie square to the upright ones (`scene_vertical`: the most edge length explained by a vertical
and two level directions at right angles, over focal lengths from 0.4 to 2.5 times the image's long side).
"""

from dataclasses import dataclass

import cv2
import numpy as np
from jaxtyping import Float

SEGMENT_MIN = 0.03  # of the image's diagonal: shorter segments (texture, a limb's outline) are left out
AGREE_RAD = np.radians(1.0)  # a segment agrees when its plane passes within this of the direction (a long
# segment's end points are found to a pixel: over 50 px or more, a degree)
SEARCH_RAD = np.radians(45.0)  # the vertical is looked for within this of the body's up (other edges lie flat,
# 90 degrees away)
SAME_LINE_PX = 2.0  # segments whose middles lie this close to one line are one edge (LSD finds edges to a pixel)
MIN_EDGES = 6  # distinct edges that must agree: two fix a direction, six within a degree do not by chance
TRIALS = 2000  # RANSAC's pairs of edges
FAMILIES = 3  # directions found, one after the other
REFINEMENTS = 3
FOCAL_RANGE = (0.4, 2.5)  # focal lengths tried, times the image's long side: fields of view from 22 to 100 degrees
FOCAL_STEPS = 60  # tried on a geometric grid (3% apart)
LEVEL_STEPS = 360  # pairs of level directions tried (a quarter of a degree apart)


@dataclass(frozen=True)
class Segments:
    """The straight edges of some frames of one camera, each the longest of its segments on one image line (the
    same edge in several frames, or cut in pieces, counts once: a direction needs that many distinct edges):
    ``ends (N, 2, 2)`` pixels, ``lengths (N,)`` the length of its segments summed."""

    ends: np.ndarray
    lengths: np.ndarray

    @classmethod
    def detect(cls, images: list[np.ndarray]) -> "Segments":
        """The edges of the segments longer than `SEGMENT_MIN` of the image's diagonal in ``images`` (BGR or
        gray)."""
        detector = cv2.createLineSegmentDetector()
        ends = [np.zeros((0, 2, 2))]
        for image in images:
            gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
            found = detector.detect(gray)[0]
            if found is not None:
                pairs = found.reshape(-1, 2, 2).astype(np.float64)
                length = np.linalg.norm(pairs[:, 1] - pairs[:, 0], axis=-1)
                ends.append(pairs[length > SEGMENT_MIN * np.hypot(*gray.shape)])
        return cls(*_merged(np.concatenate(ends)))

    @property
    def directions(self) -> np.ndarray:
        """``(N, 2)`` each edge's unit direction in the image."""
        along = self.ends[:, 1] - self.ends[:, 0]
        return along / np.linalg.norm(along, axis=-1, keepdims=True)

    def planes(self, focal_length: float, principal_point) -> np.ndarray:
        """``(N, 3)`` each edge's plane through the camera's centre as a unit normal in the camera's frame."""
        rays = np.concatenate([(self.ends - np.asarray(principal_point)) / focal_length,
                               np.ones(self.ends.shape[:2] + (1,))], -1)
        normals = np.cross(rays[:, 0], rays[:, 1])
        return normals / np.linalg.norm(normals, axis=-1, keepdims=True)

    def agree(self, directions: np.ndarray, focal_length: float, principal_point) -> np.ndarray:
        """``(N, D)``: which edges run, in the image, within `AGREE_RAD` of where each 3D direction of
        ``directions (D, 3)`` (camera frame) runs through their middle: the test is in pixels, the same for
        every focal length."""
        middle = self.ends.mean(1) - np.asarray(principal_point)  # (N, 2)
        run = focal_length * directions[None, :, :2] - middle[:, None] * directions[None, :, 2:]  # (N, D, 2)
        run /= np.maximum(np.linalg.norm(run, axis=-1, keepdims=True), 1e-12)
        along = self.directions[:, None]
        return np.abs(along[..., 0] * run[..., 1] - along[..., 1] * run[..., 0]) < np.sin(AGREE_RAD)


def _merged(ends: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segments on one image line (within `AGREE_RAD` of its direction and `SAME_LINE_PX` of it) as one edge: the
    longest one's ends, their lengths summed."""
    lengths = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=-1)
    order = np.argsort(-lengths)
    ends, lengths = ends[order], lengths[order]
    along = (ends[:, 1] - ends[:, 0]) / np.maximum(lengths[:, None], 1e-12)
    normal = np.stack([-along[:, 1], along[:, 0]], 1)
    middle = ends.mean(1)
    parallel = np.abs(along @ along.T) > np.cos(AGREE_RAD)
    near = np.abs(np.einsum("ic,jc->ij", normal, middle) - np.sum(normal * middle, 1)[:, None]) < SAME_LINE_PX
    same = parallel & near  # j's middle on i's line
    left, heads, sums = np.ones(len(ends), bool), [], []
    for i in range(len(ends)):
        if left[i]:
            members = left & same[i]
            heads.append(i)
            sums.append(lengths[members].sum())
            left &= ~members
    return ends[heads].reshape(-1, 2, 2), np.asarray(sums, np.float64)


def vertical_direction(segments: Segments, focal_length: float, principal_point, near: Float[np.ndarray, "3"],
                       seed: int = 0) -> np.ndarray | None:
    """The scene's up direction (unit, camera frame, within `SEARCH_RAD` of ``near`` and on its side) from the
    upright edges among ``segments`` seen through the lens, or None where fewer than `MIN_EDGES` agree: of the
    `FAMILIES` directions most edges agree on (`families`), the one closest to ``near``."""
    return max(families(segments, (focal_length, principal_point), near, seed), key=lambda d: d @ near, default=None)


def families(segments: Segments, lens, near: Float[np.ndarray, "3"], seed: int = 0) -> list[np.ndarray]:
    """Up to `FAMILIES` directions within `SEARCH_RAD` of ``near`` that most edges agree on through ``lens``
    (``(focal_length, principal_point)``), each found without the edges of those before."""
    near = np.asarray(near, np.float64) / np.linalg.norm(near)
    rng, found, left = np.random.default_rng(seed), [], np.ones(len(segments.lengths), bool)
    for _ in range(FAMILIES):
        direction = _family(segments, left, lens, near, rng)
        if direction is None:
            break
        found.append(direction)
        left &= ~segments.agree(direction[None], *lens)[:, 0]
    return found


def _family(segments: Segments, left: np.ndarray, lens, near: np.ndarray, rng) -> np.ndarray | None:
    """The direction within `SEARCH_RAD` of ``near`` that the longest total of the edges ``left`` agree on (RANSAC
    over pairs of them, then least squares over those agreeing), or None where fewer than `MIN_EDGES` agree."""
    if left.sum() < MIN_EDGES:
        return None
    normals = segments.planes(*lens)
    pairs = rng.choice(np.flatnonzero(left), (TRIALS, 2))
    candidates = np.cross(normals[pairs[:, 0]], normals[pairs[:, 1]])
    norms = np.linalg.norm(candidates, axis=-1)
    candidates = candidates[norms > 1e-9] / norms[norms > 1e-9, None]
    candidates *= np.sign(candidates @ near)[:, None]
    candidates = candidates[candidates @ near >= np.cos(SEARCH_RAD)]
    agree = left[:, None] & segments.agree(candidates, *lens)
    support = np.where(agree.sum(0) >= MIN_EDGES, segments.lengths @ agree, 0.0)  # (a few long edges, a frame's
    # borders, are no vertical)
    if not support.any():
        return None
    return _refined(segments, left, lens, candidates[np.argmax(support)])


def _refined(segments: Segments, left: np.ndarray, lens, direction: np.ndarray) -> np.ndarray | None:
    """Of ``direction`` and its refinements (the direction closest to the planes of the edges ``left`` agreeing
    with it: least squares, each weighed by its length; `REFINEMENTS` times), the one the longest total of edges
    agree with; None where fewer than `MIN_EDGES` agree with it."""
    normals, best, chosen = segments.planes(*lens), 0.0, None
    for _ in range(REFINEMENTS + 1):
        agree = left & segments.agree(direction[None], *lens)[:, 0]
        if agree.sum() < MIN_EDGES:
            break
        if segments.lengths @ agree >= best:  # (ties: the refined one)
            best, chosen = segments.lengths @ agree, direction
        scatter = (normals[agree] * segments.lengths[agree, None]).T @ normals[agree]
        refined = np.linalg.eigh(scatter)[1][:, 0]
        direction = refined * np.sign(refined @ direction)
    return chosen


def _square_support(segments: Segments, lens, vertical: np.ndarray) -> tuple[float, int]:
    """The edge length agreeing with the vertical or with one of two level directions at right angles to it and
    to each other (a room's or a street's three directions), the pair that most agree with; and the count of the
    edges agreeing with that pair."""
    a = np.cross(vertical, [1.0, 0.0, 0.0] if abs(vertical[0]) < 0.9 else [0.0, 1.0, 0.0])
    a /= np.linalg.norm(a)
    angles = np.linspace(0.0, np.pi / 2, LEVEL_STEPS, endpoint=False)
    first = np.cos(angles)[:, None] * a + np.sin(angles)[:, None] * np.cross(vertical, a)
    agree = segments.agree(np.concatenate([vertical[None], first, np.cross(vertical, first)]), *lens)
    level = agree[:, 1:1 + LEVEL_STEPS] | agree[:, 1 + LEVEL_STEPS:]
    best = int(np.argmax(segments.lengths @ (level | agree[:, :1])))
    return float(segments.lengths @ (level[:, best] | agree[:, 0])), int(level[:, best].sum())


def images_vertical(images: list[np.ndarray], lens, near: Float[np.ndarray, "3"], long_side: float,
                    fixed: bool = False) -> np.ndarray | None:
    """The scene's vertical near ``near`` (unit, camera frame) from the edges of ``images`` of one camera
    (`Segments.detect`, `scene_vertical` through ``lens``, its focal length ``fixed`` or searched), or None."""
    return scene_vertical(Segments.detect(images), *lens, near, long_side, fixed=fixed)[0]


def scene_vertical(segments: Segments, focal_length: float, principal_point, near: Float[np.ndarray, "3"],
                   long_side: float, fixed: bool = False) -> tuple[np.ndarray | None, float]:
    """``(vertical, focal_length)``: of the directions near ``near`` that most edges agree on (`families`, through
    ``focal_length``), the one that, with two level directions square to it and to each other, explains the most
    edge length under the focal length that explains most (the module docstring; ``fixed``: ``focal_length``
    only) -- a bundle of edges converging by chance has no level edges square to it. Each is followed from focal
    length to focal length outwards from ``focal_length`` (refined from its neighbour's). Where no focal length
    finds `MIN_EDGES` level edges: the direction closest to ``near``, through ``focal_length``; (None,
    ``focal_length``) without any."""
    found = families(segments, (focal_length, principal_point), near)
    grid = np.asarray([focal_length]) if fixed else np.geomspace(*FOCAL_RANGE, FOCAL_STEPS) * long_side
    start = int(np.searchsorted(grid, focal_length))
    every, best, chosen = np.ones(len(segments.lengths), bool), 0.0, None
    for vertical in found:
        for side in (grid[start:], grid[:start][::-1]):
            direction = vertical
            for candidate in side:
                direction = _refined(segments, every, (candidate, principal_point), direction)
                if direction is None:
                    break
                support, level = _square_support(segments, (candidate, principal_point), direction)
                if level >= MIN_EDGES and support > best:
                    best, chosen = support, (direction, float(candidate))
    if chosen is None:
        return max(found, key=lambda d: d @ near, default=None), focal_length
    return chosen
