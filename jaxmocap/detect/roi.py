"""Rotated regions of interest: building them, cropping them into a model tensor, projecting landmarks back.

Follows mediapipe's ``AlignmentPointsRectsCalculator``, ``DetectionsToRectsCalculator``,
``RectTransformationCalculator``, ``ImageToTensorCalculator`` (OpenCV path), ``LandmarkLetterboxRemovalCalculator``,
``LandmarkProjectionCalculator`` and ``WorldLandmarkProjectionCalculator``. A rect is normalized to the image
(centre, size as fractions of width/height) with a rotation in radians (clockwise in image coordinates).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np


class Rect(NamedTuple):
    """A rotated rectangle normalized to the image, like mediapipe's ``NormalizedRect``."""

    x_center: float
    y_center: float
    width: float
    height: float
    rotation: float = 0.0


def normalize_radians(angle: float) -> float:
    """``angle`` wrapped into ``[-pi, pi)``."""
    return angle - 2 * math.pi * math.floor((angle + math.pi) / (2 * math.pi))


def rotation_between(p0, p1, image_size: tuple[int, int], target_degrees: float = 90.0) -> float:
    """Rotation that turns the vector p0 -> p1 (normalized points) to ``target_degrees`` (90 = pointing up)."""
    w, h = image_size
    dx, dy = (p1[0] - p0[0]) * w, (p1[1] - p0[1]) * h
    return normalize_radians(math.radians(target_degrees) - math.atan2(-dy, dx))


def alignment_rect(center, scale_point, image_size: tuple[int, int], target_degrees: float = 90.0) -> Rect:
    """Square rect centred on ``center`` whose side is twice the distance to ``scale_point`` (in pixels)."""
    w, h = image_size
    size = 2.0 * math.hypot((scale_point[0] - center[0]) * w, (scale_point[1] - center[1]) * h)
    return Rect(float(center[0]), float(center[1]), size / w, size / h,
                rotation_between(center, scale_point, image_size, target_degrees))


def box_rect(box, p0, p1, image_size: tuple[int, int], target_degrees: float = 90.0) -> Rect:
    """Axis-aligned box (xmin, ymin, xmax, ymax) as a rect rotated by the keypoint vector p0 -> p1."""
    return Rect((box[0] + box[2]) / 2, (box[1] + box[3]) / 2, box[2] - box[0], box[3] - box[1],
                rotation_between(p0, p1, image_size, target_degrees))


def transform_rect(rect: Rect, image_size: tuple[int, int], scale: float, shift_y: float = 0.0) -> Rect:
    """``RectTransformationCalculator`` with ``square_long``: shift along the rotated y axis, square, then scale."""
    w, h = image_size
    xc, yc, rw, rh, rot = rect
    if shift_y:
        if rot == 0.0:
            yc += rh * shift_y
        else:
            xc += (-h * rh * shift_y * math.sin(rot)) / w
            yc += (h * rh * shift_y * math.cos(rot)) / h
    long_side = max(rw * w, rh * h)
    return Rect(xc, yc, long_side / w * scale, long_side / h * scale, rot)


def crop(image: np.ndarray, rect: Rect | None, size: int, value_range: tuple[float, float],
         border_zero: bool) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The (1, size, size, 3) float32 RGB tensor of ``rect`` in a BGR ``image`` (whole image if None), letterboxed.

    Returns the tensor and the letterbox padding (left, top, right, bottom) as fractions of the tensor.
    """
    matrix, padding = crop_matrix(rect, image.shape[1::-1], size)
    warped = warp_perspective(image, matrix, size, border_zero)
    lo, hi = value_range
    tensor = warped[None, :, :, ::-1].astype(np.float32) * np.float32((hi - lo) / 255.0) + np.float32(lo)
    return tensor, padding


def crop_matrix(rect: Rect | None, image_size: tuple[int, int], size: int
                ) -> tuple[np.ndarray, tuple[float, float, float, float]]:
    """The perspective matrix (3, 3) from image pixels to the ``size`` square tensor of ``rect`` (whole image if
    None), its short side grown to a square, and that letterbox padding (left, top, right, bottom) as fractions of
    the tensor."""
    iw, ih = image_size
    if rect is None:
        cx, cy, rw, rh, rot = iw / 2, ih / 2, float(iw), float(ih), 0.0
    else:
        cx, cy, rw, rh, rot = rect.x_center * iw, rect.y_center * ih, rect.width * iw, rect.height * ih, rect.rotation
    if not (rw > 0 and rh > 0) or not all(math.isfinite(v) for v in (cx, cy, rw, rh, rot)):
        raise ValueError(f"invalid region of interest {rect}")
    pad_x = pad_y = 0.0
    if rh / rw < 1.0:  # square tensor: grow the short side, record the letterbox
        pad_y = (1.0 - rh / rw) / 2
        rh = rw
    else:
        pad_x = (1.0 - rw / rh) / 2
        rw = rh
    src = cv2.boxPoints(((cx, cy), (rw, rh), math.degrees(rot)))
    dst = np.array([[0, size], [0, 0], [size, 0], [size, size]], np.float32)
    return cv2.getPerspectiveTransform(src.astype(np.float32), dst), (pad_x, pad_y, pad_x, pad_y)


def warp_perspective(image: np.ndarray, matrix: np.ndarray, size: int, border_zero: bool) -> np.ndarray:
    """``cv2.warpPerspective(image, matrix, (size, size), INTER_LINEAR)`` as OpenCV 4 and mediapipe's own build
    compute it: each output pixel's source position in double, rounded to 1/32 pixel, then `cv2.remap`'s
    fixed-point bilinear sampling. OpenCV 5's warp differs from it by a few levels in some pixels, and BlazePose's
    landmarks follow such differences by whole pixels (docs/BENCHMARKS.md, "Detector")."""
    _, m = cv2.invert(np.asarray(matrix, np.float64), flags=cv2.DECOMP_LU)  # OpenCV's own 3x3 inverse
    x = np.arange(size, dtype=np.float64)
    with np.errstate(divide="ignore"):
        w = 32.0 / _source(m[2], x)  # positions in 1/32 pixel; none where the row is at infinity
    w[np.isinf(w)] = 0.0
    fixed_x, fixed_y = _fixed(m[0], x, w), _fixed(m[1], x, w)
    whole = np.stack([fixed_x >> 5, fixed_y >> 5], axis=-1)
    np.clip(whole, -32768, 32767, out=whole)
    fraction = ((fixed_y & 31) << 5 | (fixed_x & 31)).astype(np.uint16)
    border = cv2.BORDER_CONSTANT if border_zero else cv2.BORDER_REPLICATE
    return cv2.remap(image, whole.astype(np.int16), fraction, cv2.INTER_LINEAR, borderMode=border, borderValue=0)


def _source(row: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``row[0] x + row[1] y + row[2]`` over the (y, x) grid of output pixels, summed in OpenCV's order."""
    out = (row[0] * x)[None, :] + (row[1] * x)[:, None]
    out += row[2]
    return out


def _fixed(row: np.ndarray, x: np.ndarray, w: np.ndarray) -> np.ndarray:
    """A source coordinate of each output pixel in 1/32 pixel, rounded, as int32."""
    position = _source(row, x)
    position *= w
    np.clip(position, -2.0**31, 2.0**31 - 1, out=position)
    return np.rint(position, out=position).astype(np.int32)


def project(points: np.ndarray, rect: Rect, padding) -> np.ndarray:
    """Landmarks (N, >=3) normalized to the letterboxed crop -> normalized to the image (x, y, z; z scaled as x)."""
    left, top, right, bottom = padding
    x = (points[:, 0] - left) / (1.0 - left - right) - 0.5
    y = (points[:, 1] - top) / (1.0 - top - bottom) - 0.5
    z = points[:, 2] / (1.0 - left - right)
    c, s = math.cos(rect.rotation), math.sin(rect.rotation)
    out = np.array(points, dtype=np.float64, copy=True)
    out[:, 0] = (c * x - s * y) * rect.width + rect.x_center
    out[:, 1] = (s * x + c * y) * rect.height + rect.y_center
    out[:, 2] = z * rect.width
    return out


def rotate_world(points: np.ndarray, rect: Rect) -> np.ndarray:
    """World landmarks (N, 3) rotated about z by the rect's rotation, like ``WorldLandmarkProjectionCalculator``."""
    c, s = math.cos(rect.rotation), math.sin(rect.rotation)
    out = np.array(points, dtype=np.float64, copy=True)
    out[:, 0] = c * points[:, 0] - s * points[:, 1]
    out[:, 1] = s * points[:, 0] + c * points[:, 1]
    return out
