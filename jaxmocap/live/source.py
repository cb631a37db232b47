"""Frames of a webcam, a stream or a video file, as they come: read in a thread into a `Mailbox`, the newest
replacing one not yet taken (a dropped frame). A file plays as fast as it is taken (nothing dropped), or with
``realtime`` at its own frame rate, as a camera would deliver it: then each frame is decoded when it is due (a
video's frames depend on each other) but converted to an image only if it is taken before the next is due, so
the frames dropped cost their decoding alone (the conversion to BGR is as long again). A camera's or a stream's
read waits for its next frame, so each of theirs is converted as it comes."""

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
    source without one is a `MediaError`); ``read``: frames read; `dropped`: those not taken."""

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
        self.read, self._unconverted = 0, 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="jaxmocap-source", daemon=True)

    @property
    def dropped(self) -> int:
        """Frames read but not taken: replaced in `frames` before they were, or never asked for."""
        return self.frames.dropped + self._unconverted

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
        start, played, this_play, first = time.perf_counter(), 0, 0, self._first
        timed = not (self.live or self.lossless)  # a file in real time: each frame converted only when asked for
        grabbed = None  # (timed) the newest frame decoded, its image not yet converted
        try:
            while not self._stop.is_set():
                due = start + self.read / self.fps
                if timed:
                    if grabbed is not None and self.frames.asked(due - time.perf_counter()):
                        self._hand_over(grabbed)
                        grabbed = None
                        continue
                    if self._stop.wait(max(0.0, due - time.perf_counter())):
                        return
                if first is not None:
                    ok, image, first = True, first, None
                elif timed:
                    ok, image = self.capture.grab(), None
                else:
                    ok, image = self.capture.read()
                    ok = ok and image is not None
                if not ok:  # the end: again from the start, unless the file cannot be played again
                    played, self._unconverted, grabbed = played + 1, self._unconverted + (grabbed is not None), None
                    if self.live or (self.loops and played >= self.loops) or this_play == 0:
                        return
                    self.capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
                    this_play = 0
                    continue
                if timed:
                    self._unconverted += grabbed is not None
                    grabbed = (self.read, image, due)
                else:
                    self.frames.put(Frame(self.read, image, time.perf_counter()), wait=self.lossless)
                self.read, this_play = self.read + 1, this_play + 1
        finally:
            self.capture.release()
            self.frames.close()

    def _hand_over(self, grabbed: tuple[int, np.ndarray | None, float]) -> None:
        """Puts the grabbed frame (its number, its image where it has one, when it was due), its image converted
        now (none put where the file gives none for it)."""
        index, image, due = grabbed
        if image is None:
            ok, image = self.capture.retrieve()
            if not ok or image is None:
                self._unconverted += 1
                return
        self.frames.put(Frame(index, image, due))
