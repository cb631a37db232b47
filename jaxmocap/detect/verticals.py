"""The scene's vertical direction seen from a static camera: the vanishing direction of the straight edges that
stand upright (door frames, corners of walls, furniture, poles), among the line segments of a few frames (OpenCV's
LSD detector). Through the lens, a segment spans a plane through the camera's centre; segments parallel to a
direction ``d`` have planes that contain it (their unit normals ``l`` have ``l · d = 0``). ``d`` is looked for
near the up direction the body suggests (RANSAC over pairs of segments, scored by the length of those that agree),
then refined by least squares over those; None where too few edges agree.

The direction is as exact as the lens: a focal length off by 15% tilts it by some 3 degrees in a camera looking
down by 20 degrees (``--focal-length`` gives the true one).
"""

import cv2
import numpy as np
from jaxtyping import Float

SEGMENT_MIN = 0.03  # of the image's diagonal: shorter segments (texture, a limb's outline) are left out
AGREE_RAD = np.radians(1.0)  # a segment agrees when its plane passes within this of the direction (a long
# segment's end points are found to a pixel: over 50 px or more, a degree)
SEARCH_RAD = np.radians(45.0)  # the vertical is looked for within this of the body's up (other edges lie flat,
# 90 degrees away)
MIN_EDGES = 6  # distinct edges that must agree: two fix a direction, six within a degree do not by chance
TRIALS = 2000  # RANSAC's pairs of segments
FAMILIES = 3  # directions found, one after the other
REFINEMENTS = 3


def segment_planes(images: list[np.ndarray], focal_length: float, principal_point) -> tuple[np.ndarray, np.ndarray]:
    """``(normals (N, 3), lengths (N,))``: the planes through the camera's centre of the long segments, as unit
    normals in the camera's frame, and their lengths in pixels; segments on one line (within `AGREE_RAD`: the
    same edge in several frames, or cut in pieces) are one plane, their lengths summed, so that a direction needs
    that many distinct edges."""
    detector = cv2.createLineSegmentDetector()
    inverse = np.linalg.inv(np.array([[focal_length, 0.0, principal_point[0]], [0.0, focal_length, principal_point[1]],
                                      [0.0, 0.0, 1.0]]))
    normals, lengths = [np.zeros((0, 3))], [np.zeros(0)]
    for image in images:
        gray = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.ndim == 3 else image
        found = detector.detect(gray)[0]
        if found is None:
            continue
        ends = found.reshape(-1, 2, 2).astype(np.float64)
        length = np.linalg.norm(ends[:, 1] - ends[:, 0], axis=-1)
        keep = length > SEGMENT_MIN * np.hypot(*gray.shape)
        rays = np.concatenate([ends[keep], np.ones((int(keep.sum()), 2, 1))], -1) @ inverse.T
        normal = np.cross(rays[:, 0], rays[:, 1])
        normals.append(normal / np.linalg.norm(normal, axis=-1, keepdims=True))
        lengths.append(length[keep])
    return _merged(np.concatenate(normals), np.concatenate(lengths))


def _merged(normals: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Planes within `AGREE_RAD` of a longer one merged into it (its normal kept, the lengths summed)."""
    order = np.argsort(-lengths)
    normals, lengths = normals[order], lengths[order]
    same = np.abs(normals @ normals.T) > np.cos(AGREE_RAD)
    left, heads, sums = np.ones(len(normals), bool), [], []
    for i in range(len(normals)):
        if left[i]:
            members = left & same[i]
            heads.append(i)
            sums.append(lengths[members].sum())
            left &= ~members
    return normals[heads].reshape(-1, 3), np.asarray(sums, np.float64)


def vertical_direction(images: list[np.ndarray], focal_length: float, principal_point,
                       near: Float[np.ndarray, "3"], seed: int = 0) -> np.ndarray | None:
    """The scene's up direction (unit, camera frame, within `SEARCH_RAD` of ``near`` and on its side) from the
    upright edges of ``images`` (BGR or gray, one static camera), or None where fewer than `MIN_EDGES` agree. Of
    the `FAMILIES` directions that most segments agree on (each found without the segments of those before), the
    one closest to ``near``: other bundles of segments (a floor's edges converging in the image) can outnumber the
    upright ones."""
    normals, lengths = segment_planes(images, focal_length, principal_point)
    near = np.asarray(near, np.float64) / np.linalg.norm(near)
    rng, found = np.random.default_rng(seed), []
    left = np.ones(len(normals), bool)
    for _ in range(FAMILIES):
        direction = _family(normals[left], lengths[left], near, rng)
        if direction is None:
            break
        found.append(direction)
        left &= np.abs(normals @ direction) >= np.sin(AGREE_RAD)
    return max(found, key=lambda d: d @ near, default=None)


def _family(normals: np.ndarray, lengths: np.ndarray, near: np.ndarray, rng) -> np.ndarray | None:
    """The direction within `SEARCH_RAD` of ``near`` that the longest total of segments agree on (RANSAC over
    pairs, then least squares over those agreeing), or None where fewer than `MIN_EDGES` agree."""
    if len(normals) < MIN_EDGES:
        return None
    best, direction = 0.0, None
    for a, b in rng.integers(0, len(normals), (TRIALS, 2)):
        candidate = np.cross(normals[a], normals[b])
        if np.linalg.norm(candidate) < 1e-9:
            continue
        candidate = candidate / np.linalg.norm(candidate) * np.sign(candidate @ near)
        if candidate @ near < np.cos(SEARCH_RAD):
            continue
        support = lengths[np.abs(normals @ candidate) < np.sin(AGREE_RAD)].sum()
        if support > best:
            best, direction = support, candidate
    for _ in range(REFINEMENTS if direction is not None else 0):  # the direction closest to every agreeing plane
        agree = np.abs(normals @ direction) < np.sin(AGREE_RAD)
        if agree.sum() < MIN_EDGES:
            return None
        scatter = (normals[agree] * lengths[agree, None]).T @ normals[agree]
        refined = np.linalg.eigh(scatter)[1][:, 0]
        direction = refined * np.sign(refined @ direction)
    return direction
