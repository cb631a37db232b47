"""Frames of a webcam, a stream or a video file, as they come: read in a thread into a `Mailbox`, the newest
replacing one not yet taken (a dropped frame). A file plays as fast as it is taken (nothing dropped), or with
``realtime`` at its own frame rate, as a camera would deliver it."""

import threading
import time
from dataclasses import dataclass

import cv2
import numpy as np

from jaxmocap.frame_source import MediaError, capture
from jaxmocap.live.mailbox import Mailbox


@dataclass(frozen=True)
class Frame:
    """A frame of the source: its number (from 0, counting every frame the source gave), the BGR image and when
    it came (`time.perf_counter` seconds: for a file played in real time, when it was due)."""

    index: int
    image: np.ndarray
    arrived: float


def is_live(source) -> bool:
    """Whether ``source`` is a webcam index or a stream URL (frames come at the device's pace), not a file."""
    return str(source).isdigit() or "://" in str(source)


class LiveSource:
    """Reads ``source`` in a thread into `frames` until its end (a file played ``loops`` times; 0: for ever) or
    `stop`. ``fps``: the source's frame rate; ``size``: (width, height) of its first frame, read on opening (a
    source without one is a `MediaError`); ``read``: frames read; ``frames.dropped``: those replaced before they
    were taken."""

    def __init__(self, source, realtime: bool = False, loops: int = 1):
        self.capture = capture(source)
        ok, self._first = self.capture.read()
        if not ok or self._first is None:
            self.capture.release()
            raise MediaError(f"{source} gave no frames (empty, unsupported, or a file served without seeking)")
        self.size = (self._first.shape[1], self._first.shape[0])
        self.live = is_live(source)
        self.fps = float(self.capture.get(cv2.CAP_PROP_FPS) or 0.0) or 30.0
        self.lossless = not (self.live or realtime)
        self.loops = loops
        self.frames = Mailbox()
        self.read = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="jaxmocap-source", daemon=True)

    def start(self) -> "LiveSource":
        self._thread.start()
        return self

    def stop(self, timeout: float) -> None:
        """Ends the reading within ``timeout`` seconds, or leaves it behind (a daemon thread): a stalled stream's
        read may never return."""
        self._stop.set()
        self.frames.close()
        self._thread.join(timeout)

    def _run(self) -> None:
        start, played, image, this_play = time.perf_counter(), 0, self._first, 0
        try:
            while not self._stop.is_set():
                due = start + self.read / self.fps
                if not (self.live or self.lossless) and self._stop.wait(max(0.0, due - time.perf_counter())):
                    return
                if image is None:
                    ok, image = self.capture.read()
                if image is None:  # the end: again from the start, unless the file cannot be played again
                    played += 1
                    if self.live or (self.loops and played >= self.loops) or this_play == 0:
                        return
                    self.capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
                    this_play = 0
                    continue
                arrived = time.perf_counter() if (self.live or self.lossless) else due
                self.frames.put(Frame(self.read, image, arrived), wait=self.lossless)
                self.read, this_play, image = self.read + 1, this_play + 1, None
        finally:
            self.capture.release()
            self.frames.close()
