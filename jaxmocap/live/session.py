"""``jaxmocap live``: frames in as they come, whole-body SMPL-X out as they are solved.

Three threads overlap the stages, handing frames on through one-item `Mailbox` es (nothing waits but the newest):
the source reads frames (`LiveSource`); detection runs the tracking detector and the identities; the caller's
thread solves each person causally (`CausalSolver`), sends the frame's message (`stream`) and records it; with a
viewer a fourth renders the overlay for the web page (`Viewer`). A stage that falls behind drops the frames it
could not take (counted); a file played as fast as it can be (no ``realtime``) drops nothing.
"""

import contextlib
import dataclasses
import functools
import signal
import sys
import threading
import time
from array import array
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import jax
import numpy as np

import smplx_jax
from jaxmocap.detect import Detector
from jaxmocap.detect.detector import search_interval
from jaxmocap.detect.identities import IdentityTracker
from jaxmocap.detect.models import LANDMARK_MODELS, available_landmarks
from jaxmocap.errors import InputError
from jaxmocap.frame_source import STREAM_TIMEOUT_S
from jaxmocap.live.causal import CausalSolver, LiveSettings, Solved
from jaxmocap.live.mailbox import Closed, Mailbox
from jaxmocap.live.record import CLOSE_SECONDS, Recorder
from jaxmocap.live.source import Frame, LiveSource
from jaxmocap.live.stream import UdpSender, frame_message, person_message
from jaxmocap.live.viewer import Viewer
from jaxmocap.live.world import LiveWorld
from jaxmocap.overlay import Posed, people_over_frame
from jaxmocap.pipeline.config import MODES
from jaxmocap.pipeline.observe import Observations, observe_people
from jaxmocap.pipeline.stages import lens_of
from jaxmocap.result_files import file_sha256
from jaxmocap.signals import handling


@dataclass(frozen=True)
class LiveConfig:
    """``jaxmocap live SOURCE [options]`` as one value.

    ``source``: a webcam index, a stream URL or a video file; ``mode``: ``whole`` (body and hands), ``body`` (no
    hand model runs, hands flat) or ``hands`` (hands alone, up to ``max_hands``: `jaxmocap.live.hands`);
    ``realtime``: play a file at its frame rate, as a camera would deliver it (frames dropped when the solve falls
    behind), else as fast as it is solved, every frame; ``loops``: times a file plays (0: until stopped).
    ``max_people``: people tracked at most. ``landmarks``: BlazePose's landmark model (``full`` where the one asked
    for cannot be fetched). ``serve``: the web page's port (None: no page) on ``host``; ``udp``:
    ``(host, port)`` to send each frame's JSON line to; ``record``: a folder to write the motions to as they are
    solved (as ``jaxmocap run`` does; `jaxmocap.live.record`). ``max_frames``: stop after that many frames
    solved. ``view_height``: the page's frame height in pixels.
    """

    source: str | Path
    mode: str = "whole"
    realtime: bool = False
    loops: int = 1
    max_people: int = 1
    max_hands: int = 2
    landmarks: str = "full"
    serve: int | None = None
    host: str = "127.0.0.1"
    udp: tuple[str, int] | None = None
    record: Path | None = None
    model: Path | None = None
    focal_length: float | None = None
    max_frames: int | None = None
    view_height: int = 540
    progress: bool = True
    settings: LiveSettings = field(default_factory=LiveSettings)

    def __post_init__(self):
        checks = (("mode", self.mode in MODES), ("loops", self.loops >= 0), ("max_people", self.max_people >= 1),
                  ("max_hands", self.max_hands >= 1), ("landmarks", self.landmarks in LANDMARK_MODELS),
                  ("serve", self.serve is None or 0 <= self.serve < 65536),
                  ("max_frames", self.max_frames is None or self.max_frames >= 1),
                  ("view_height", self.view_height >= 64),
                  ("focal_length", self.focal_length is None or self.focal_length > 0))
        for name, ok in checks:
            if not ok:
                raise InputError(f"live: bad {name} {getattr(self, name)!r}")


@dataclass(frozen=True)
class LiveReport:
    """What a live session did: frames read from the source, solved and dropped; seconds from the first frame
    read to the last result; each solved frame's latency (ms, from its arrival to its parameters out); why it
    stopped; files written; each stage's time on each frame it ran on (ms, by stage: ``detect``, ``fit``,
    ``world``, ``output`` (the UDP message and the recording), ``draw`` (the page's overlay and its JPEG))."""

    read: int
    solved: int
    dropped: int
    seconds: float
    latency_ms: np.ndarray
    stopped: str
    written: list[Path]
    stage_ms: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def fps(self) -> float:
        return self.solved / max(self.seconds, 1e-9)

    def summary(self) -> str:
        lat = self.latency_ms if len(self.latency_ms) else np.zeros(1)
        return (f"{self.stopped}: {self.solved} of {self.read} frames solved in {self.seconds:.1f} s "
                f"({self.fps:.1f} frames/s), {self.dropped} dropped, latency median {np.median(lat):.0f} ms, "
                f"95th percentile {np.percentile(lat, 95):.0f} ms")


_VERTICES = jax.jit(lambda model, params: smplx_jax.forward(model, params).vertices)
# Seconds a stop waits for each thread: time to finish the frame in hand (a frame's detection, solve or drawing
# takes a fraction of it) or for a stalled stream's read to time out (`frame_source.STREAM_TIMEOUT_S`: a read still
# pending as the process exits can crash it); a thread still running after it is left behind, a daemon thread,
# rather than keep the process alive.
STOP_SECONDS = STREAM_TIMEOUT_S + 1.0
FLOOR_WAIT_SECONDS = 10.0  # the longest a session's end waits for its floor being found (a second or two)


class Session:
    """The threads and their hand-offs (`live`); a subclass solves another mode (its `_setup`, `_observe`,
    `_solve`, `_posed`)."""

    noun = "people"  # what the status line counts

    def __init__(self, config: LiveConfig):
        self.config = config
        model_path = smplx_jax.model_path(config.model)
        self.model = smplx_jax.load_model(model_path)
        self.sender = None if config.udp is None else UdpSender(config.udp)
        self.source = LiveSource(config.source, config.realtime, config.loops)
        self.lens = lens_of(self.source.size, config.focal_length)
        self.detected, self.shown = Mailbox(), Mailbox()
        self.errors: list[BaseException] = []
        self.stats = {"fps": 0.0, "latency_ms": 0.0, "dropped": 0, "solved": 0, self.noun: 0}
        self.stage_ms: dict[str, array] = {}  # doubles: 8 bytes a frame and stage however long the session runs
        self.recorder = self.viewer = self.world = None
        try:
            self._setup(file_sha256(model_path))
            self.viewer = None if config.serve is None else self._viewer()
        except BaseException:
            self.close()
            raise

    def _viewer(self) -> Viewer:
        try:
            return Viewer(self.config.host, self.config.serve)
        except OSError as err:
            raise InputError(f"--serve: cannot listen on {self.config.host}:{self.config.serve} "
                             f"({err.strerror})") from None

    def _setup(self, model_sha256: str) -> None:
        """The detector, the solver and the recorder of the mode."""
        config, hands = self.config, self.config.mode == "whole"
        self.solver = CausalSolver(self.model, self.lens, dataclasses.replace(config.settings, hands=hands))
        landmarks = available_landmarks(config.landmarks)
        self.detector = Detector(static_image_mode=False, max_people=config.max_people, hands=hands,
                                 redetect_every=search_interval(self.source.fps), landmarks=landmarks)
        self.tracker = IdentityTracker()
        self.world = LiveWorld(self.model, self.lens, max(self.source.size), fixed=config.focal_length is not None)
        self.recorder = None if config.record is None else Recorder(
            config.record, self.model, model_sha256, self.lens, self.source.fps, self.source.size, landmarks,
            world=self.world)

    def close(self) -> None:
        """Release the source, the page and the stream, then write the recording's last frames (all idempotent)."""
        self.source.capture.release()
        for closable in (self.viewer, self.sender):
            if closable is not None:
                closable.close()
        if self.world is not None:
            self.world.settle(FLOOR_WAIT_SECONDS)  # the recording stands on the floor being found
        if self.recorder is not None:
            self.recorder.close(CLOSE_SECONDS)

    def warm_up(self) -> None:
        """Compile the solve, the world frame's joints, the recording's rows (and the viewer's mesh) before the
        first frame comes."""
        self.solver.warm_up()
        if self.world is not None:
            self.world.warm_up()
        if self.recorder is not None:
            self.recorder.warm_up()
        if self.viewer is not None:
            jax.block_until_ready(_VERTICES(self.model, smplx_jax.SMPLXParams.zeros(self.model.num_betas,
                                                                                      self.model.num_expression)))

    def _thread(self, target) -> threading.Thread:
        def guarded():
            try:
                target()
            except Closed:
                pass
            except BaseException as err:  # handed to the caller's thread
                self.errors.append(err)
            finally:
                self.detected.close()
                self.shown.close()

        thread = threading.Thread(target=guarded, name=f"jaxmocap-{target.__name__.strip('_')}", daemon=True)
        thread.start()
        return thread

    @contextlib.contextmanager
    def _stage(self, name: str):
        """Times the block as one frame's ``name`` stage (`LiveReport.stage_ms`)."""
        start = time.perf_counter()
        yield
        self.stage_ms.setdefault(name, array("d")).append(1000 * (time.perf_counter() - start))

    def _detect(self) -> None:
        while True:
            frame = self.source.frames.get()
            with self._stage("detect"):
                people = self._observe(frame.image)
            self.detected.put((frame, people), wait=self.source.lossless)

    def _observe(self, image: np.ndarray) -> dict[int, Observations]:
        """What the solve needs of one frame: each person's observations by identity (with ``--max-people 1``
        always identity 0: one person, whoever the tracker thinks it is after a restart or a drop-out)."""
        people = observe_people(self.detector, self.tracker, [image])
        if self.config.max_people == 1:
            return dict(enumerate(people.values()))  # at most one: identity 0
        return people

    def _posed(self, solved: dict[int, Solved]) -> list[Posed]:
        """The meshes the page draws of one frame's results."""
        return [Posed(i, np.asarray(_VERTICES(self.model, s.params)), float(s.camera_scale), s.camera_trans)
                for i, s in solved.items() if s.valid]

    def _render(self) -> None:
        faces = np.asarray(self.model.faces)
        scale = min(1.0, self.config.view_height / self.source.size[1])
        while True:
            frame, solved = self.shown.get()
            if not self.viewer.wanted():  # nobody watching, or every viewer still busy with the last frame
                continue
            with self._stage("draw"):
                image = people_over_frame(frame.image, self._posed(solved), faces, scale, *self.lens)
                stats = self.stats
                cv2.putText(image, f"{stats['fps']:.1f} frames/s  {stats['latency_ms']:.0f} ms", (10, 24),
                            cv2.FONT_HERSHEY_SIMPLEX, 0.6, (255, 255, 255), 2, cv2.LINE_AA)
                ok, jpeg = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 80])
            if ok:
                self.viewer.publish(jpeg.tobytes())  # (its rates: `_update_stats`)

    def _solve(self, frame: Frame, people: dict[int, Observations]) -> dict[int, Solved]:
        now = frame.arrived if self.source.live else frame.index / self.source.fps
        with self._stage("fit"):
            solved = self.solver(people, now)
        with self._stage("world"):
            world = self.world.keys(now, solved, frame.image)
        with self._stage("output"):
            if self.sender is not None:
                camera_from_world = self.world.camera_from_world  # (set after the floor)
                floor = None if camera_from_world is None else self.world.floor.array
                self.sender.send(frame_message(frame.index, now, [
                    person_message(i, s.params, s.camera_scale, s.camera_trans, people[i].keypoints[0], world.get(i))
                    for i, s in solved.items() if s.valid], floor=floor, camera_from_world=camera_from_world))
            if self.recorder is not None:
                self.recorder.add(frame.index, now, solved, {i: o.keypoints[0] for i, o in people.items()})
        return solved

    def run(self) -> LiveReport:
        threads = [self._thread(self._detect)] + ([self._thread(self._render)] if self.viewer else [])
        self.source.start()
        latencies, stopped, first, last, shown_at = array("d"), "end of stream", None, None, 0.0
        try:
            while self.config.max_frames is None or len(latencies) < self.config.max_frames:
                try:
                    frame, people = self.detected.get(timeout=0.25)
                except TimeoutError:
                    continue
                except Closed:
                    break
                solved = self._solve(frame, people)
                last = time.perf_counter()
                first = frame.arrived if first is None else first
                latencies.append(1000 * (last - frame.arrived))
                if self.viewer is not None:
                    self.shown.put((frame, solved))
                if last - shown_at > 1.0:
                    shown_at = last
                    self._update_stats(latencies, len(solved), last - first)
            else:
                stopped = "max frames"
        except KeyboardInterrupt:
            stopped = "interrupted"
        except BaseException as err:  # (the recording's writing failed) stopped as the other threads' errors
            self.errors.append(err)
        with _sheltered():  # a second Ctrl-C (or SIGTERM) while stopping must not lose the recording
            self.source.stop(STOP_SECONDS)
            self.detected.close()
            self.shown.close()
            for thread in threads:
                thread.join(STOP_SECONDS)
            self.close()
            if self.config.progress:
                print(file=sys.stderr)
            if self.errors:
                raise self.errors[0]
            return self._finish(latencies, stopped, 0.0 if first is None else last - first)

    def _dropped(self) -> int:
        return self.source.dropped + self.detected.dropped

    def _update_stats(self, latencies: array, count: int, seconds: float) -> None:
        recent = latencies[-60:]
        self.stats = {"fps": len(latencies) / max(seconds, 1e-9), "latency_ms": float(np.median(recent)),
                      "dropped": self._dropped(), "solved": len(latencies), self.noun: count}
        if self.viewer is not None:  # the page's rates, also while no frame is drawn
            self.viewer.stats = self.stats
        if self.config.progress:
            s = self.stats
            print(f"\rlive: {s['fps']:.1f} frames/s, latency {s['latency_ms']:.0f} ms, {s['dropped']} dropped, "
                  f"{count} {self.noun}", end="", file=sys.stderr, flush=True)

    def _finish(self, latencies: array, stopped: str, seconds: float) -> LiveReport:
        written = [] if self.recorder is None else self.recorder.written
        return LiveReport(self.source.read, len(latencies), self._dropped(), seconds, np.asarray(latencies), stopped,
                          written, {name: np.asarray(ms) for name, ms in self.stage_ms.items()})


_sheltered = functools.partial(handling, signal.SIG_IGN, signal.SIGINT, signal.SIGTERM)  # Ctrl-C and SIGTERM ignored

