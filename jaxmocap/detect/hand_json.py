"""``jaxmocap detect --mode hands``: hands alone (no body) as OpenPose JSON per frame of a video, image folder or
image."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from ..frame_source import MediaError, open_media
from .detector import as_bgr, search_interval
from .draw import draw_openpose
from .hand_tracker import SIDES, Hand, HandTracker
from .openpose import json_name, write_openpose_json


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
    from tqdm import tqdm

    media, frames = open_media(input)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    still = media.kind in ("image", "images")
    tracker = HandTracker(static_image_mode=still, max_hands=max_hands, model_dir=model_dir,
                          redetect_every=search_interval(media.fps))
    written: list[Path] = []
    writer = None
    if overlay and still:
        (out / "overlay").mkdir(exist_ok=True)
    try:
        for n, (index, frame) in enumerate(tqdm(frames, total=media.frame_count, desc="detect hands",
                                                 unit="img" if still else "frame", disable=not progress)):
            try:
                image = as_bgr(frame)
            except ValueError as err:
                raise MediaError(f"{input}: frame {index}: {err}") from None
            keypoints, ids = hands_openpose(*_rows(tracker(image)), max_hands)
            name = json_name(media.stems[n], None) if still else json_name(media.stem, index)
            written.append(write_openpose_json(out / name, keypoints, ids, body=False))
            if overlay and still:
                cv2.imwrite(str(out / "overlay" / f"{media.stems[n]}.jpg"), draw_openpose(image, keypoints))
            elif overlay:
                if writer is None:
                    writer = cv2.VideoWriter(str(out / f"{media.stem}_overlay.mp4"),
                                             cv2.VideoWriter_fourcc(*"mp4v"), media.fps, media.size)
                writer.write(draw_openpose(image, keypoints))
    finally:
        if writer is not None:
            writer.release()
    return written
