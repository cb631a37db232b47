"""BlazePose as mediapipe 0.10.21's ``PoseLandmarkCpu`` graph runs it: detector, ROI, 33 landmarks (the full, heavy
or lite landmark model: the same inputs and outputs).

Detector (``PoseDetectionCpu``): whole image letterboxed to 224, values in [-1, 1], zero border; SSD anchors
(5 layers, strides 8/16/32/32/32); keypoints 0 (mid hip) and 1 (scale/rotation) give the ROI (``PoseDetectionToRoi``:
target angle 90°, ×1.25, square long). Landmarks (``PoseLandmarkByRoiCpu``): ROI warped to 256, values in [0, 1],
replicated border; 39 landmarks × (x, y, z, visibility, presence), heatmap refinement (kernel 9), presence ≥ 0.5.
Tracking (``PoseLandmarksToRoi``): auxiliary landmarks 33 (centre) and 34 (scale) give the next ROI.
"""

from __future__ import annotations

from typing import NamedTuple

import cv2
import numpy as np

from .models import TFLiteModel
from .roi import Rect, alignment_rect, crop, crop_matrix, project, rotate_world, transform_rect
from .ssd import Detection, decode, remove_letterbox, ssd_anchor_centers, weighted_nms

DETECTOR_SIZE = 224
LANDMARK_SIZE = 256
ROI_SCALE = 1.25
# the refinement's window: its options' default, 9, is what 0.10.21's legacy graph runs (measured on 14 stills:
# 9 reproduces its landmarks to 1e-4 of a heatmap cell, the 7 of its .pbtxt misses by 0.07 cells, ~1.5 px)
HEATMAP_KERNEL = 9
MIN_DETECTION_SCORE = 0.5
MIN_PRESENCE = 0.5


class PoseResult(NamedTuple):
    """One person's pose: ``landmarks`` (33, 5) normalized x, y, z, visibility, presence; ``world`` (33, 3) metres;
    ``presence`` score; ``roi`` the rect the landmarks came from; ``next_roi`` the tracking rect for the next frame."""

    landmarks: np.ndarray
    world: np.ndarray
    presence: float
    roi: Rect
    next_roi: Rect


def _sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def refine_from_heatmap(landmarks: np.ndarray, heatmap: np.ndarray, kernel: int = HEATMAP_KERNEL,
                        min_confidence: float = 0.5) -> np.ndarray:
    """Replace x, y by the sigmoid-weighted centroid of the heatmap window around each landmark.

    Mirrors ``RefineLandmarksFromHeatmapCalculator`` (including its truncating int cast and its bounds check, which
    compares the column with the heatmap height).
    """
    hh, hw, n = heatmap.shape
    off = (kernel - 1) // 2
    cols = (landmarks[:, 0] * hw).astype(np.int64)  # truncation toward zero, like the C++ int cast
    rows = (landmarks[:, 1] * hh).astype(np.int64)
    inside = (cols >= 0) & (cols < hw) & (rows >= 0) & (cols < hh)
    # the window shrinks at the heatmap borders (cells outside weigh nothing), as in the calculator
    k = np.arange(kernel) - off
    r_val, c_val = rows[:, None] + k, cols[:, None] + k  # (n, kernel) heatmap coordinates of each window
    r_ok, c_ok = (r_val >= 0) & (r_val < hh), (c_val >= 0) & (c_val < hw)
    raw = heatmap[np.clip(r_val, 0, hh - 1)[:, :, None], np.clip(c_val, 0, hw - 1)[:, None, :],
                  np.arange(n)[:, None, None]]
    win = _sigmoid(raw.astype(np.float64)) * (r_ok[:, :, None] & c_ok[:, None, :])
    total = win.sum((1, 2))
    ok = inside & (win.max((1, 2)) >= min_confidence) & (total > 0)
    safe = np.where(total > 0, total, 1.0)
    out = landmarks.copy()
    out[ok, 0] = ((win.sum(1) * c_val).sum(1) / hw / safe)[ok]
    out[ok, 1] = ((win.sum(2) * r_val).sum(1) / hh / safe)[ok]
    return out


class PoseEstimator:
    """Person detector + pose landmark model; ``detect`` finds people, ``landmarks`` runs one ROI."""

    def __init__(self, detector_path, landmark_path, num_threads: int = 2):
        self._detector = TFLiteModel(detector_path, num_threads)
        self._landmarker = TFLiteModel(landmark_path, num_threads)
        self._anchors = ssd_anchor_centers(DETECTOR_SIZE, [8, 16, 32, 32, 32])

    def detect(self, image: np.ndarray, min_score: float = MIN_DETECTION_SCORE) -> list[Detection]:
        """Person detections on a BGR image, best first, normalized to the image."""
        tensor, padding = crop(image, None, DETECTOR_SIZE, (-1.0, 1.0), border_zero=True)
        raw_boxes, raw_scores = self._detector(tensor)
        dets = decode(raw_boxes[0], raw_scores[0], self._anchors, DETECTOR_SIZE, 4, min_score)
        return [remove_letterbox(d, padding) for d in weighted_nms(dets, 0.3)]

    @staticmethod
    def detection_roi(det: Detection, image_size: tuple[int, int]) -> Rect:
        """The landmark ROI of a person detection (mid-hip centre, keypoint 1 sets size and rotation)."""
        return transform_rect(alignment_rect(det.keypoints[0], det.keypoints[1], image_size), image_size, ROI_SCALE)

    def landmarks(self, image: np.ndarray, roi: Rect, min_presence: float = MIN_PRESENCE) -> PoseResult | None:
        """The pose inside ``roi`` of a BGR image, or None when the model says no person is there."""
        return self.observe(image, roi, min_presence)[0]

    def observe(self, image: np.ndarray, roi: Rect, min_presence: float = MIN_PRESENCE
                ) -> tuple[PoseResult | None, Silhouette]:
        """The pose inside ``roi`` of a BGR image (None when the model says no person is there), and the
        person's silhouette, from one run of the landmark model."""
        ih, iw = image.shape[:2]
        tensor, padding = crop(image, roi, LANDMARK_SIZE, (0.0, 1.0), border_zero=False)
        raw, flag, segmentation, heatmap, raw_world = self._landmarker(tensor)
        silhouette = Silhouette(segmentation[0, :, :, 0].astype(np.float32), roi)
        presence = float(flag.reshape(-1)[0])
        if presence < min_presence:
            return None, silhouette
        lm = raw.reshape(39, 5).astype(np.float64)
        norm = np.empty_like(lm)
        norm[:, :3] = lm[:, :3] / LANDMARK_SIZE
        norm[:, 3:] = _sigmoid(lm[:, 3:])
        norm = refine_from_heatmap(norm, heatmap[0])
        image_lm = project(norm, roi, padding)
        world = rotate_world(raw_world.reshape(39, 3)[:33].astype(np.float64), roi)
        next_roi = transform_rect(alignment_rect(image_lm[33, :2], image_lm[34, :2], (iw, ih)), (iw, ih), ROI_SCALE)
        return PoseResult(image_lm[:33], world, presence, roi, next_roi), silhouette


class Silhouette(NamedTuple):
    """The landmark model's segmentation of the person in ``roi``: ``logits`` (256, 256) over the ROI's crop."""

    logits: np.ndarray
    roi: Rect

    def mask(self, image_size: tuple[int, int]) -> np.ndarray:
        """(H, W) bool for an image of ``image_size`` (width, height): the pixels the model holds more likely the
        person's than not (none outside the ROI)."""
        matrix, _ = crop_matrix(self.roi, image_size, LANDMARK_SIZE)
        inside = (self.logits > 0).astype(np.uint8)
        return cv2.warpPerspective(inside, matrix, image_size, flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP) > 0


def rect_extent(r: Rect) -> tuple[float, float, float, float]:
    """The axis-aligned extent (x0, y0, x1, y1) of a rect, normalized units, its rotation left out."""
    return r.x_center - r.width / 2, r.y_center - r.height / 2, r.x_center + r.width / 2, r.y_center + r.height / 2


def overlap(a, b) -> float:
    """The area two boxes (x0, y0, x1, y1) have in common."""
    return max(0.0, min(a[2], b[2]) - max(a[0], b[0])) * max(0.0, min(a[3], b[3]) - max(a[1], b[1]))


def rect_iou(a: Rect, b: Rect) -> float:
    """IoU of the axis-aligned extents of two rects (normalized units); used to drop duplicate people."""
    inter = overlap(rect_extent(a), rect_extent(b))
    union = a.width * a.height + b.width * b.height - inter
    return inter / union if union > 0 else 0.0


def landmark_box(landmarks: np.ndarray, image_size: tuple[int, int], min_visibility: float = 0.0) -> np.ndarray:
    """Pixel box (x0, y0, x1, y1) of the landmarks whose visibility is at least ``min_visibility`` (all if none)."""
    w, h = image_size
    pts = landmarks[landmarks[:, 3] >= min_visibility, :2] if min_visibility > 0 else landmarks[:, :2]
    if len(pts) == 0:
        pts = landmarks[:, :2]
    pts = pts * (w, h)
    return np.array([pts[:, 0].min(), pts[:, 1].min(), pts[:, 0].max(), pts[:, 1].max()])

