"""Skeleton overlays for checking detections by eye."""

from __future__ import annotations

import cv2
import numpy as np

BODY25_EDGES = [(1, 8), (1, 2), (2, 3), (3, 4), (1, 5), (5, 6), (6, 7), (8, 9), (9, 10), (10, 11), (8, 12),
                (12, 13), (13, 14), (1, 0), (0, 15), (15, 17), (0, 16), (16, 18), (14, 19), (14, 21), (11, 22),
                (11, 24)]
HAND_EDGES = [(0, 1), (1, 2), (2, 3), (3, 4), (0, 5), (5, 6), (6, 7), (7, 8), (0, 9), (9, 10), (10, 11), (11, 12),
              (0, 13), (13, 14), (14, 15), (15, 16), (0, 17), (17, 18), (18, 19), (19, 20)]


def draw_openpose(image: np.ndarray, keypoints: np.ndarray, min_confidence: float = 0.3) -> np.ndarray:
    """A copy of a BGR image with (P, 67, 3) OpenPose keypoints drawn (body green, left hand blue, right red)."""
    out = image.copy()
    thickness = max(1, round(max(image.shape[:2]) / 400))
    parts = [(0, BODY25_EDGES, (0, 220, 0)), (25, HAND_EDGES, (255, 120, 0)), (46, HAND_EDGES, (0, 0, 255))]
    for person in keypoints:
        for offset, edges, color in parts:
            for a, b in edges:
                pa, pb = person[offset + a], person[offset + b]
                if pa[2] >= min_confidence and pb[2] >= min_confidence:
                    cv2.line(out, (int(pa[0]), int(pa[1])), (int(pb[0]), int(pb[1])), color, thickness, cv2.LINE_AA)
            for x, y, c in person[offset:offset + (25 if offset == 0 else 21)]:
                if c >= min_confidence:
                    cv2.circle(out, (int(x), int(y)), thickness + 1, color, -1, cv2.LINE_AA)
    return out
