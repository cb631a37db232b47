"""SSD detector head as mediapipe decodes it: anchors, box/keypoint decoding, weighted NMS, letterbox removal.

Numbers come from the calculator options of mediapipe 0.10.21's ``PoseDetectionCpu`` / ``PalmDetectionCpu`` graphs
(``SsdAnchorsCalculator``, ``TensorsToDetectionsCalculator``, ``NonMaxSuppressionCalculator``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np


class Detection(NamedTuple):
    """One detection, normalized to the image: ``box`` (xmin, ymin, xmax, ymax), ``keypoints`` (K, 2) as x, y."""

    score: float
    box: np.ndarray
    keypoints: np.ndarray


def ssd_anchor_centers(input_size: int, strides: list[int]) -> np.ndarray:
    """Anchor centres (N, 2) for ``fixed_anchor_size`` SSD anchors with aspect ratio 1 plus one interpolated scale.

    Consecutive layers sharing a stride are merged into one grid with 2 anchors per layer per cell, as
    ``SsdAnchorsCalculator`` does (anchor width and height are 1 with ``fixed_anchor_size``).
    """
    centers = []
    layer = 0
    while layer < len(strides):
        same = layer
        while same < len(strides) and strides[same] == strides[layer]:
            same += 1
        per_cell = 2 * (same - layer)
        size = int(np.ceil(input_size / strides[layer]))
        ys, xs = np.meshgrid(np.arange(size), np.arange(size), indexing="ij")
        grid = np.stack([(xs + 0.5) / size, (ys + 0.5) / size], axis=-1).reshape(-1, 1, 2)
        centers.append(np.repeat(grid, per_cell, axis=1).reshape(-1, 2))
        layer = same
    return np.concatenate(centers).astype(np.float32)


def decode(raw_boxes: np.ndarray, raw_scores: np.ndarray, anchors: np.ndarray, scale: float,
           num_keypoints: int, min_score: float) -> list[Detection]:
    """Decode raw (N, 4+2K) boxes and (N,) logits above ``min_score`` (score = sigmoid of the clipped logit)."""
    scores = 1.0 / (1.0 + np.exp(-np.clip(raw_scores.reshape(-1).astype(np.float64), -100.0, 100.0)))
    keep = np.nonzero(scores >= min_score)[0]
    out = []
    for i in keep[np.argsort(-scores[keep], kind="stable")]:
        r = raw_boxes[i].astype(np.float64)
        ax, ay = anchors[i]
        cx, cy = r[0] / scale + ax, r[1] / scale + ay
        w, h = r[2] / scale, r[3] / scale
        if w < 0 or h < 0:
            continue
        kps = r[4:4 + 2 * num_keypoints].reshape(num_keypoints, 2) / scale + (ax, ay)
        out.append(Detection(float(scores[i]), np.array([cx - w / 2, cy - h / 2, cx + w / 2, cy + h / 2]), kps))
    return out


def _area(boxes: np.ndarray):
    return (boxes[..., 2] - boxes[..., 0]) * (boxes[..., 3] - boxes[..., 1])


def _iou(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    x0 = np.maximum(box[0], boxes[:, 0])
    y0 = np.maximum(box[1], boxes[:, 1])
    x1 = np.minimum(box[2], boxes[:, 2])
    y1 = np.minimum(box[3], boxes[:, 3])
    inter = np.clip(x1 - x0, 0, None) * np.clip(y1 - y0, 0, None)
    union = _area(box) + _area(boxes) - inter
    return np.where(union > 0, inter / np.where(union > 0, union, 1), 0.0)


def weighted_nms(detections: list[Detection], threshold: float = 0.3) -> list[Detection]:
    """Weighted non-maximum suppression: each kept detection is the score-weighted mean of its IoU > threshold
    cluster."""
    remaining = sorted(detections, key=lambda d: -d.score)
    out = []
    while remaining:
        top = remaining[0]
        boxes = np.stack([d.box for d in remaining])
        cluster = _iou(top.box, boxes) > threshold
        members = [d for d, c in zip(remaining, cluster) if c]
        if members:
            w = np.array([d.score for d in members])
            box = (np.stack([d.box for d in members]) * w[:, None]).sum(0) / w.sum()
            kps = (np.stack([d.keypoints for d in members]) * w[:, None, None]).sum(0) / w.sum()
            out.append(Detection(top.score, box, kps))
        else:
            out.append(top)
        rest = [d for d, c in zip(remaining, cluster) if not c]
        if len(rest) == len(remaining):
            break
        remaining = rest
    return out


def remove_letterbox(det: Detection, padding: tuple[float, float, float, float]) -> Detection:
    """Map a detection from the letterboxed tensor back to the original image (padding left, top, right, bottom)."""
    left, top, right, bottom = padding
    sx, sy = 1.0 - left - right, 1.0 - top - bottom
    box = (det.box - (left, top, left, top)) / (sx, sy, sx, sy)
    kps = (det.keypoints - (left, top)) / (sx, sy)
    return Detection(det.score, box, kps)


def square_tiles(image_size: tuple[int, int]) -> list[tuple[int, int, int]]:
    """Squares (x0, y0, side) of the image's short side along its long side, evenly spaced, neighbours
    overlapping by half a side or more; none for an image within 1.25:1 of square (the whole image is one)."""
    w, h = image_size
    side, length = min(w, h), max(w, h)
    if length < 1.25 * side:
        return []
    starts = np.linspace(0, length - side, math.ceil(2 * (length - side) / side) + 1).round()
    return [(0, int(s), side) if h > w else (int(s), 0, side) for s in starts]


def in_image(det: Detection, tile: tuple[int, int, int], image_size: tuple[int, int]) -> Detection:
    """A detection made on the square ``tile`` (x0, y0, side) of an image, normalized to the whole image."""
    x0, y0, side = tile
    w, h = image_size
    scale, offset = np.array([side / w, side / h]), np.array([x0 / w, y0 / h])
    return Detection(det.score, det.box * np.tile(scale, 2) + np.tile(offset, 2), det.keypoints * scale + offset)
