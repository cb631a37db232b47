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
        self.read, self._put = 0, 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="jaxmocap-source", daemon=True)

    @property
    def dropped(self) -> int:
        """Frames read but not taken: never put into `frames` (not asked for), or replaced there before taken."""
        return self.read - self._put + self.frames.dropped

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
                    played, grabbed = played + 1, None
                    if self.live or (self.loops and played >= self.loops) or this_play == 0:
                        return
                    self.capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
                    this_play = 0
                    continue
                index, self.read, this_play = self.read, self.read + 1, this_play + 1  # (read before put: `dropped`)
                if timed:
                    grabbed = (index, image, due)
                else:
                    self._hand_over((index, image, time.perf_counter()))
        finally:
            self.capture.release()
            self.frames.close()

    def _hand_over(self, grabbed: tuple[int, np.ndarray | None, float]) -> None:
        """Puts the frame read (its number, its image, or None where it was grabbed and not yet converted, when it
        came) into `frames`, converting it now (none put where the file gives none for it)."""
        index, image, arrived = grabbed
        if image is None:
            ok, image = self.capture.retrieve()
            if not ok or image is None:
                return
        self.frames.put(Frame(index, image, arrived), wait=self.lossless)
        self._put += 1
