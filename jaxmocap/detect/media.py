"""Run the detector over a video file, an image folder or a single image and write OpenPose JSON per frame."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Iterator

import cv2
import numpy as np

from ..errors import InputError
from .detector import Detector, Person, as_bgr
from .draw import draw_openpose
from .openpose import body25_from_blazepose, hand21, json_name, write_openpose_json

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp", ".jp2", ".pgm", ".ppm", ".pnm"}


class MediaError(InputError):
    """The input cannot be read as a video, an image folder or an image (the message names it)."""


def to_openpose(people: list[Person]) -> np.ndarray:
    """(P, 67, 3) OpenPose keypoints (BODY_25, left hand, right hand) of detected people, in pixels."""
    out = np.zeros((len(people), 67, 3))
    for i, p in enumerate(people):
        out[i, :25] = body25_from_blazepose(p.body)
        out[i, 25:46] = hand21(p.left_hand, p.left_hand_score)
        out[i, 46:67] = hand21(p.right_hand, p.right_hand_score)
    return out


def read_image(path: str | os.PathLike) -> np.ndarray:
    """An image file as decoded by OpenCV (any depth/channels; ``Detector`` converts), or ``MediaError``."""
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None or image.size == 0:
        raise MediaError(f"cannot read image {path} (missing, empty or not an image format OpenCV can decode)")
    return image


def _video_frames(path: Path) -> tuple[int, float, Iterator[np.ndarray]]:
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        raise MediaError(f"cannot open {path} as a video or image (unsupported or corrupt file)")
    ok, first = cap.read()
    if not ok or first is None:
        cap.release()
        raise MediaError(f"video {path} has no readable frames")
    total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
    fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0) or 30.0

    def frames():
        try:
            frame = first
            while frame is not None:
                yield frame
                ok, frame = cap.read()
                if not ok:
                    break
        finally:
            cap.release()

    return total, fps, frames()


def detect_media(input: str | os.PathLike, out_dir: str | os.PathLike, overlay: bool = False,
                 progress: bool = True, *, max_people: int = 1, model_dir: str | os.PathLike | None = None,
                 hands: bool = True) -> list[Path]:
    """Detect people in a video file (tracking mode), an image folder or one image (static mode).

    Writes one OpenPose JSON per frame/image into ``out_dir`` (``<stem>_<frame:012d>_keypoints.json`` for video
    frames, ``<stem>_keypoints.json`` for images; ``"people": []`` when nobody is found) and, with ``overlay``,
    skeleton images (``out_dir/overlay/<stem>.jpg``) or a video (``out_dir/<stem>_overlay.mp4``).
    Returns the JSON paths in frame order. Raises ``MediaError`` for unreadable input (and ``ModelFileError``
    when the model files cannot be had).
    """
    from tqdm import tqdm

    src = Path(input)
    if not src.exists():
        raise MediaError(f"input {src} does not exist")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []

    if src.is_dir() or src.suffix.lower() in IMAGE_SUFFIXES:
        files = sorted(p for p in src.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES) if src.is_dir() else [src]
        if not files:
            raise MediaError(f"folder {src} holds no images ({', '.join(sorted(IMAGE_SUFFIXES))})")
        detector = Detector(static_image_mode=True, max_people=max_people, hands=hands, model_dir=model_dir)
        if overlay:
            (out / "overlay").mkdir(exist_ok=True)
        for path in tqdm(files, desc="detect", unit="img", disable=not progress):
            image = as_bgr(read_image(path))
            keypoints = to_openpose(detector(image))
            written.append(write_openpose_json(out / json_name(path.stem, None), keypoints))
            if overlay:
                cv2.imwrite(str(out / "overlay" / f"{path.stem}.jpg"), draw_openpose(image, keypoints))
        return written

    total, fps, frames = _video_frames(src)
    detector = Detector(static_image_mode=False, max_people=max_people, hands=hands, model_dir=model_dir)
    writer = None
    try:
        for index, frame in enumerate(tqdm(frames, total=total or None, desc="detect", unit="frame",
                                           disable=not progress)):
            keypoints = to_openpose(detector(frame))
            written.append(write_openpose_json(out / json_name(src.stem, index), keypoints))
            if overlay:
                if writer is None:
                    h, w = frame.shape[:2]
                    writer = cv2.VideoWriter(str(out / f"{src.stem}_overlay.mp4"),
                                             cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
                writer.write(draw_openpose(frame, keypoints))
    finally:
        if writer is not None:
            writer.release()
    return written
