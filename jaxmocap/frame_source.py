"""Frames from a video file, an image folder, a single image or a webcam, decoded in a background thread."""

import queue
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from jaxmocap.errors import InputError

IMAGE_SUFFIXES = {".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp", ".jp2", ".pgm", ".ppm", ".pnm"}


class MediaError(InputError):
    """The input cannot be read as a video, an image folder, an image or a webcam (the message names it)."""


@dataclass(frozen=True)
class Media:
    """An opened input. ``kind``: ``video``, ``images``, ``image`` or ``webcam``; ``size`` (width, height) of the
    first frame; ``frame_count`` after ``start``/``end``/``stride`` (None for a webcam); ``stems`` and ``paths``: one
    name and file per image for ``images``/``image``."""

    kind: str
    stem: str
    fps: float
    size: tuple[int, int]
    frame_count: int | None
    stems: tuple[str, ...] = ()
    paths: tuple[Path, ...] = ()


def read_image(path) -> np.ndarray:
    """An image file as an 8-bit BGR array, turned upright as its EXIF orientation says (a phone's portrait photo),
    or `MediaError`; grayscale, 16-bit and alpha images are converted."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None or image.size == 0:
        raise MediaError(f"cannot read image {path} (missing, empty or not an image format OpenCV can decode)")
    return image


# Seconds of silence after which a network stream has ended: a camera sends several frames a second, and a read
# that never returns would otherwise hold its thread (and the process) for ever.
STREAM_TIMEOUT_S = 3.0

def capture(source) -> cv2.VideoCapture:
    """An opened `cv2.VideoCapture` of a webcam index, a stream URL or a video file, or `MediaError`. A stream
    that sends nothing for `STREAM_TIMEOUT_S` (opening it, or between frames) has ended: its read returns no frame."""
    if not str(source).isdigit() and "://" not in str(source) and not Path(source).exists():
        raise MediaError(f"input {source} does not exist")
    if str(source).isdigit():
        cap = cv2.VideoCapture(int(source))
    elif "://" in str(source):
        timeout_ms = int(1000 * STREAM_TIMEOUT_S)
        cap = cv2.VideoCapture(str(source), cv2.CAP_ANY, [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, timeout_ms,
                                                          cv2.CAP_PROP_READ_TIMEOUT_MSEC, timeout_ms])
    else:
        cap = cv2.VideoCapture(str(source))
    if not cap.isOpened():
        if str(source).isdigit():
            raise MediaError(f"cannot open webcam {source} (no camera with that index, or it is busy)")
        raise MediaError(f"cannot open {source} as a video or image (unsupported, corrupt or busy)")
    return cap


def _video(cap, start, end, stride) -> Iterator[tuple[int, np.ndarray]]:
    index = 0
    try:
        while end is None or index < end:
            ok, frame = cap.read()
            if not ok or frame is None:
                return
            if index >= start and (index - start) % stride == 0:
                yield index, frame
            index += 1
    finally:
        cap.release()


PREFETCH_STOP_SECONDS = STREAM_TIMEOUT_S + 1.0  # the decoding thread's end: a frame's decoding or a stream's timeout


def _prefetch(frames: Iterator, depth: int = 8) -> Iterator:
    """The same items, decoded ahead in a background thread (decoding overlaps the work on earlier frames). When
    the consumer stops, the thread stops too (`PREFETCH_STOP_SECONDS` at most), its source closed: a thread still
    decoding as the process exits can crash it."""
    items: queue.Queue = queue.Queue(maxsize=depth)
    done, stop = object(), threading.Event()

    def put(item) -> bool:
        while not stop.is_set():
            try:
                items.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def work():
        try:
            for item in frames:
                if not put(item):
                    return
            put(done)
        except BaseException as err:  # handed to the consumer
            put(err)
        finally:
            if hasattr(frames, "close"):
                frames.close()

    thread = threading.Thread(target=work, name="jaxmocap-decode", daemon=True)
    thread.start()
    try:
        while (item := items.get()) is not done:
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop.set()
        thread.join(PREFETCH_STOP_SECONDS)


def sample_frames(path, indices: list[int]) -> list[np.ndarray]:
    """The video's frames ``indices`` (BGR), each found by seeking; those it cannot give are left out."""
    cap = capture(path)
    try:
        frames = []
        for index in indices:
            cap.set(cv2.CAP_PROP_POS_FRAMES, index)
            ok, frame = cap.read()
            if ok and frame is not None:
                frames.append(frame)
        return frames
    finally:
        cap.release()


def open_media(source, start: int = 0, end: int | None = None, stride: int = 1) -> tuple[Media, Iterator]:
    """The input's description and an iterator of ``(frame index, BGR frame)`` over frames
    ``start, start + stride, ... < end``. Video frames are decoded ahead in a background thread."""
    if start < 0 or stride < 1 or (end is not None and end <= start):
        raise MediaError(f"bad frame range start={start} end={end} stride={stride}")
    if str(source).isdigit():
        cap = capture(source)
        fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0) or 30.0
        size = (int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)))
        return Media("webcam", f"webcam{source}", fps / stride, size, None), _video(cap, start, end, stride)
    path = Path(source)
    if not path.exists():
        raise MediaError(f"input {path} does not exist")
    if path.is_dir() or path.suffix.lower() in IMAGE_SUFFIXES:
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES) if path.is_dir() else [path]
        files = files[start:end:stride]
        if not files:
            raise MediaError(f"folder {path} holds no images ({', '.join(sorted(IMAGE_SUFFIXES))}) in that range")
        first = read_image(files[0])
        kind = "images" if path.is_dir() else "image"
        media = Media(kind, path.stem, 30.0, (first.shape[1], first.shape[0]), len(files),
                      tuple(f.stem for f in files), tuple(files))
        return media, ((start + i * stride, read_image(f)) for i, f in enumerate(files))

    cap = capture(path)
    total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
    fps = float(cap.get(cv2.CAP_PROP_FPS) or 0.0) or 30.0
    frames = _video(cap, start, end, stride)
    first = next(frames, None)
    if first is None:
        raise MediaError(f"video {path} has no readable frames" + (f" from frame {start}" if start else ""))
    last = min(total, end) if end is not None and total else (end or total)
    count = len(range(start, last, stride)) if last else None
    size = (first[1].shape[1], first[1].shape[0])

    def chained():
        yield first
        yield from frames

    return Media("video", path.stem, fps / stride, size, count), _prefetch(chained())
