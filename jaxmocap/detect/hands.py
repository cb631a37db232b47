"""Hand landmarks as mediapipe 0.10.21's ``HandLandmarkTrackingCpu`` runs them, plus pose-seeded hand ROIs.

Palm detector (``PalmDetectionCpu``): whole image letterboxed to 192, values in [0, 1], zero border; SSD anchors
(4 layers, strides 8/16/16/16), 7 keypoints; ROI (``PalmDetectionDetectionToRoi``): box rotated by keypoint 0 -> 2,
shift -0.5 along y, ×2.6, square long. Landmarks (``HandLandmarkCpu``): ROI warped to 224, values in [0, 1],
replicated border; 21 × (x, y, z) with z / 0.4, presence ≥ 0.5, handedness, world landmarks. Tracking
(``HandLandmarkLandmarksToRoi``): landmarks 0,1,2,3,5,6,9,10,13,14,17,18 give a rotated box, shift -0.1, ×2.0.
From the pose, as holistic does (``HandLandmarksFromPoseCpu``): wrist, pinky and index of the body give a ROI
(×2.7, shift -0.1), its recrop model (256, values in [0, 1], replicated border) a centre and a scale point for a
better one (-90 degrees, shift -0.1, ×1), which replaces the tracked ROI unless that one is close to it
(``RoiTrackingCalculator``: rotation within 40 degrees, centre within 0.2 and size within 0.4 of its size, the
previous landmarks inside it shrunk by 0.1).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .models import TFLiteModel
from .roi import (
    Rect,
    alignment_rect,
    box_rect,
    crop,
    normalize_radians,
    project,
    rotate_world,
    rotation_between,
    transform_rect,
)
from .ssd import Detection, decode, remove_letterbox, ssd_anchor_centers, weighted_nms

PALM_SIZE = 192
LANDMARK_SIZE = 224
RECROP_SIZE = 256
MIN_PALM_SCORE = 0.5
MIN_PRESENCE = 0.5
_PARTIAL = [0, 1, 2, 3, 5, 6, 9, 10, 13, 14, 17, 18]
# BlazePose indices of (wrist, pinky, index) per side
POSE_HAND_POINTS = {"left": (15, 17, 19), "right": (16, 18, 20)}


class HandResult(NamedTuple):
    """One hand: ``landmarks`` (21, 3) normalized x, y, z; ``world`` (21, 3) metres; ``presence``; ``right_score``:
    probability that it is the person's right hand (mediapipe's mirrored "Left" score); ``roi``; ``next_roi``."""

    landmarks: np.ndarray
    world: np.ndarray
    presence: float
    right_score: float
    roi: Rect
    next_roi: Rect


def landmarks_roi(landmarks: np.ndarray, image_size: tuple[int, int]) -> Rect:
    """Tracking ROI from 21 normalized hand landmarks (``HandLandmarksToRectCalculator`` + transformation)."""
    w, h = image_size
    pts = landmarks[_PARTIAL, :2]
    mid = ((pts[4] + pts[8]) / 2 + pts[6]) / 2  # mean of index/ring MCP, averaged with middle MCP
    rot = rotation_between(pts[0], mid, image_size)
    center = (pts.min(0) + pts.max(0)) / 2
    px = (pts - center) * (w, h)
    c, s = math.cos(-rot), math.sin(-rot)
    proj = np.stack([px[:, 0] * c - px[:, 1] * s, px[:, 0] * s + px[:, 1] * c], axis=1)
    pc = (proj.min(0) + proj.max(0)) / 2
    size = proj.max(0) - proj.min(0)
    cx = pc[0] * math.cos(rot) - pc[1] * math.sin(rot) + w * center[0]
    cy = pc[0] * math.sin(rot) + pc[1] * math.cos(rot) + h * center[1]
    rect = Rect(cx / w, cy / h, size[0] / w, size[1] / h, rot)
    return transform_rect(rect, image_size, 2.0, shift_y=-0.1)


def pose_hand_roi(body: np.ndarray, side: str, image_size: tuple[int, int], scale: float = 2.7) -> Rect:
    """Hand ROI from the body's wrist, pinky and index landmarks (normalized), as holistic's
    ``HandDetectionsFromPoseToRectsCalculator`` builds it before its recrop model."""
    w, h = image_size
    wrist, pinky, index = (body[i, :2] for i in POSE_HAND_POINTS[side])
    middle = (2 * index + pinky) / 3
    size = 2 * math.hypot((middle[0] - wrist[0]) * w, (middle[1] - wrist[1]) * h)
    rect = Rect(float(middle[0]), float(middle[1]), size / w, size / h, rotation_between(wrist, middle, image_size))
    return transform_rect(rect, image_size, scale, shift_y=-0.1)


def _in_rect_frame(points: np.ndarray, rect: Rect, image_size: tuple[int, int]) -> np.ndarray:
    """Normalized points (N, >=2) in pixels relative to the rect's centre, along its rotated axes."""
    w, h = image_size
    d = (points[:, :2] - (rect.x_center, rect.y_center)) * (w, h)
    c, s = math.cos(rect.rotation), math.sin(rect.rotation)
    return np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)


def keeps_tracking(previous: HandResult, recrop: Rect, image_size: tuple[int, int]) -> bool:
    """Whether the previous frame's tracking ROI stays (holistic's ``RoiTrackingCalculator``) instead of the
    recrop ROI: close to it in rotation, centre and size, and the previous landmarks well inside it."""
    w, h = image_size
    rect = previous.next_roi
    if abs(math.degrees(normalize_radians(rect.rotation - recrop.rotation))) > 40.0:
        return False
    rw, rh = recrop.width * w, recrop.height * h
    dx, dy = np.abs(_in_rect_frame(np.array([[rect.x_center, rect.y_center]]), recrop, image_size)[0])
    if dx > 0.2 * rw or dy > 0.2 * rh:
        return False
    if abs(rect.width * w - rw) > 0.4 * rw or abs(rect.height * h - rh) > 0.4 * rh:
        return False
    inside = np.abs(_in_rect_frame(previous.landmarks, recrop, image_size)) < 0.5 * (1 - 0.1) * np.array([rw, rh])
    return bool(inside.all())


class HandEstimator:
    """Palm detector, hand landmark model and holistic's hand recrop model (not loaded without ``recrop_path``:
    hands found without a body)."""

    def __init__(self, palm_path, landmark_path, recrop_path=None, num_threads: int = 2):
        self._palm = TFLiteModel(palm_path, num_threads)
        self._landmarker = TFLiteModel(landmark_path, num_threads)
        self._recrop = None if recrop_path is None else TFLiteModel(recrop_path, num_threads)
        self._anchors = ssd_anchor_centers(PALM_SIZE, [8, 16, 16, 16])

    def detect(self, image: np.ndarray, min_score: float = MIN_PALM_SCORE) -> list[Detection]:
        """Palm detections on a BGR image, best first, normalized to the image."""
        tensor, padding = crop(image, None, PALM_SIZE, (0.0, 1.0), border_zero=True)
        raw_boxes, raw_scores = self._palm(tensor)
        dets = decode(raw_boxes[0], raw_scores[0], self._anchors, PALM_SIZE, 7, min_score)
        return [remove_letterbox(d, padding) for d in weighted_nms(dets, 0.3)]

    @staticmethod
    def detection_roi(det: Detection, image_size: tuple[int, int]) -> Rect:
        """Hand ROI of a palm detection."""
        rect = box_rect(det.box, det.keypoints[0], det.keypoints[2], image_size)
        return transform_rect(rect, image_size, 2.6, shift_y=-0.5)

    def recrop_roi(self, image: np.ndarray, roi: Rect) -> Rect:
        """The hand ROI that the recrop model finds inside a pose-derived ``roi`` of a BGR image."""
        size = (image.shape[1], image.shape[0])
        tensor, padding = crop(image, roi, RECROP_SIZE, (0.0, 1.0), border_zero=False)
        points = np.zeros((2, 3))
        points[:, :2] = self._recrop(tensor)[0].reshape(2, 2) / RECROP_SIZE
        centre, scale_point = project(points, roi, padding)[:, :2]
        return transform_rect(alignment_rect(centre, scale_point, size, -90.0), size, 1.0, shift_y=-0.1)

    def landmarks(self, image: np.ndarray, roi: Rect, min_presence: float = MIN_PRESENCE) -> HandResult | None:
        """The hand inside ``roi`` of a BGR image, or None when the model finds none."""
        ih, iw = image.shape[:2]
        tensor, padding = crop(image, roi, LANDMARK_SIZE, (0.0, 1.0), border_zero=False)
        raw, flag, handedness, raw_world = self._landmarker(tensor)
        presence = float(flag.reshape(-1)[0])
        if presence < min_presence:
            return None
        lm = raw.reshape(21, 3).astype(np.float64) / LANDMARK_SIZE
        lm[:, 2] /= 0.4
        image_lm = project(lm, roi, padding)
        world = rotate_world(raw_world.reshape(21, 3).astype(np.float64), roi)
        return HandResult(image_lm, world, presence, float(handedness.reshape(-1)[0]), roi,
                          landmarks_roi(image_lm, (iw, ih)))
