"""Run the detector over a video file, an image folder or a single image and write OpenPose JSON per frame (in a
video each person with a stable ``person_id``)."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np

from ..frame_source import MediaError, open_media
from .detector import Detector, Person, as_bgr, search_interval
from .draw import draw_openpose
from .identities import IdentityTracker, identify
from .models import available_landmarks
from .openpose import body25_from_blazepose, hand21, json_name, write_openpose_json

__all__ = ["detect_media", "to_openpose"]


def to_openpose(people: list[Person]) -> np.ndarray:
    """(P, 67, 3) OpenPose keypoints (BODY_25, left hand, right hand) of detected people, in pixels."""
    out = np.zeros((len(people), 67, 3))
    for i, p in enumerate(people):
        out[i, :25] = body25_from_blazepose(p.body)
        out[i, 25:46] = hand21(p.left_hand, p.left_hand_score)
        out[i, 46:67] = hand21(p.right_hand, p.right_hand_score)
    return out


def detect_media(input: str | os.PathLike, out_dir: str | os.PathLike, overlay: bool = False,
                 progress: bool = True, *, max_people: int = 1, model_dir: str | os.PathLike | None = None,
                 hands: bool = True, landmarks: str = "heavy") -> list[Path]:
    """Detect people in a video file or webcam (tracking mode), an image folder or one image (static mode).

    Writes one OpenPose JSON per frame/image into ``out_dir`` (``<stem>_<frame:012d>_keypoints.json`` for video
    frames, ``<stem>_keypoints.json`` for images; ``"people": []`` when nobody is found) and, with ``overlay``,
    skeleton images (``out_dir/overlay/<stem>.jpg``) or a video (``out_dir/<stem>_overlay.mp4``). ``landmarks``:
    BlazePose's landmark model (``full`` where it cannot be fetched, `available_landmarks`).
    Returns the JSON paths in frame order. Raises ``MediaError`` for unreadable input (and ``ModelFileError``
    when the model files cannot be had).
    """
    landmarks = available_landmarks(landmarks, model_dir)

    def detect_in(media, still):
        detector = Detector(static_image_mode=still, max_people=max_people, hands=hands, model_dir=model_dir,
                            redetect_every=search_interval(media.fps), landmarks=landmarks)
        tracker = None if still else IdentityTracker()

        def keypoints_of(image):
            people = detector(image)
            ids = identify(tracker, image, people)
            order = np.argsort(ids, kind="stable")
            return to_openpose([people[k] for k in order]), [ids[k] for k in order] if tracker else None
        return keypoints_of

    return write_detections(input, out_dir, overlay, progress, "detect", detect_in)


def write_detections(input, out_dir, overlay: bool, progress: bool, desc: str, detect_in, body: bool = True
                     ) -> list[Path]:
    """`detect_media`'s loop over the frames of ``input``: ``detect_in(media, still)`` makes the per-image
    ``(keypoints (P, 67, 3), person ids or None)`` function; the JSON (``body``: with BODY_25, else hands only)
    and the overlays are written as `detect_media` says."""
    from tqdm import tqdm

    media, frames = open_media(input)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    still = media.kind in ("image", "images")
    keypoints_of = detect_in(media, still)
    written: list[Path] = []
    writer = None
    if overlay and still:
        (out / "overlay").mkdir(exist_ok=True)
    try:
        for n, (index, frame) in enumerate(tqdm(frames, total=media.frame_count, desc=desc,
                                                 unit="img" if still else "frame", disable=not progress)):
            try:
                image = as_bgr(frame)
            except ValueError as err:
                raise MediaError(f"{input}: frame {index}: {err}") from None
            keypoints, ids = keypoints_of(image)
            name = json_name(media.stems[n], None) if still else json_name(media.stem, index)
            written.append(write_openpose_json(out / name, keypoints, ids, body=body))
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
