"""``jaxmocap detect --mode hands``: hands alone (no body) as OpenPose JSON per frame of a video, image folder or
image."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from smplx_jax import SIDES

from .hand_tracker import Hand, HandTracker
from .json_output import write_detections


def hands_openpose(sides, keypoints, scores, hand_ids, max_hands: int = 2) -> tuple[np.ndarray, list[int] | None]:
    """(P, 67, 3) OpenPose keypoints of the ``N`` hands of one image, no body, and their ``person_id`` list: with up
    to two hands one person holding the likeliest left and right hand (ids None); with more, each hand its own
    person (its id). Per hand: ``sides (N,)`` 0 left, 1 right; ``keypoints (N, 21, 3)`` pixels and confidence;
    ``scores (N,)`` presence; ``hand_ids (N,)``."""
    order = np.argsort(np.asarray(scores), kind="stable")  # the likeliest of a side last: it wins the shared slot
    one = max_hands <= 2
    people = np.zeros((min(1, len(order)) if one else len(order), 67, 3))
    for k, i in enumerate(order):
        start = 25 + 21 * int(sides[i])
        people[0 if one else k, start:start + 21] = keypoints[i]
    return people, None if one else [int(hand_ids[i]) for i in order]


def _rows(hands: list[Hand]):
    """`hands_openpose`'s arguments of the tracker's hands."""
    keypoints = np.asarray([h.keypoints_2d for h in hands]).reshape(-1, 21, 3)
    return [SIDES.index(h.side) for h in hands], keypoints, [h.score for h in hands], [h.hand_id for h in hands]


def detect_hands_media(input: str | os.PathLike, out_dir: str | os.PathLike, overlay: bool = False,
                       progress: bool = True, *, max_hands: int = 2, model_dir: str | os.PathLike | None = None
                       ) -> list[Path]:
    """Hands in a video file or webcam (tracked), an image folder or one image (each on its own), written as in
    `detect_media` (the same names and overlays), hands only: ``"pose_keypoints_2d": []``, as OpenPose writes with
    ``--body 0`` (`hands_openpose`). Returns the JSON paths in frame order."""
    def detect_in(media, still):
        tracker = HandTracker(static_image_mode=still, max_hands=max_hands, model_dir=model_dir)
        return lambda image: hands_openpose(*_rows(tracker(image)), max_hands)

    return write_detections(input, out_dir, overlay, progress, "detect hands", detect_in, body=False)
