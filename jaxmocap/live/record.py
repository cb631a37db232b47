"""A live session's results written as it goes, as ``jaxmocap run`` writes them: ``motion.npz`` (the main person)
and ``people/<id>/motion.npz`` (`Recorder`; ``hands.npz`` in hands mode: `jaxmocap.live.hands.HandRecorder`), with
which source frame each row is (``frame_index``, ``time_s``).

The solve hands each frame over (`Recording.add`); every `FLUSH_SECONDS` a thread appends the frames since the last
flush to columns on disk (`jaxmocap.columns`, in the hidden folder `JOURNAL` beside the files) and rewrites each
file from them, atomically. Memory holds only the frames since the last flush however long the session runs, and a
crash, a kill or a power cut loses those at most; `Recording.close` writes the rest and removes the journal. Each
flush rewrites the files whole: its cost grows with the recording (about 1.5 kB a frame a person)."""

import shutil
import threading
from pathlib import Path

import jax
import numpy as np

import smplx_jax
from jaxmocap.columns import Columns, write_npz
from jaxmocap.integrate import fitting
from jaxmocap.integrate.clip import FOOT_JOINTS
from jaxmocap.integrate.motion_arrays import body_joints
from jaxmocap.live.causal import Solved
from jaxmocap.live.world import LiveWorld, world_columns
from jaxmocap.motion import PINHOLE_SHAPES
from jaxmocap.pipeline.stages import Lens, motion_arrays
from jaxmocap.pipeline.tracks import Bodies
from jaxmocap.result_files import result_arrays

FLUSH_SECONDS = 5.0  # the most of a session a crash loses, and how often the files are rewritten
JOURNAL = ".recording"
CLOSE_SECONDS = 60.0  # the longest a session's end waits for its last frames written (the files rewritten whole)
BACKFILL_ROWS = 1024  # a person first seen late: their earlier frames (absent) appended this many at a time
FEET = ".feet"  # a person's heels and toes in the journal: the columns ``<id>.feet``, not a file's


class Recording:
    """The frames a session solves (`add`), written to ``folder`` as they come (module docstring). A subclass says
    what rows a batch of frames makes in each file's columns (`_rows`) and writes the files from them (`_write`);
    ``meta``: the arrays every file holds besides its columns."""

    bools: tuple[str, ...] = ()  # the columns stored as bool
    nothing: tuple = ()  # what `add` is given of a frame where nothing was seen

    def __init__(self, folder, meta: dict[str, np.ndarray], every_s: float = FLUSH_SECONDS):
        self.folder, self.meta = Path(folder), meta
        self.journal = self.folder / JOURNAL
        shutil.rmtree(self.journal, ignore_errors=True)  # a crashed session's: its files hold what it kept
        self.frames = Columns(self.journal / "frames")  # frame_index, time_s
        self.columns: dict[str, Columns] = {}
        self.written: list[Path] = []
        self.error: BaseException | None = None
        self._pending: list[tuple] = []
        self._adding, self._flushing, self._stop = threading.Lock(), threading.Lock(), threading.Event()
        self._thread = threading.Thread(target=self._keep_writing, args=(every_s,), name="jaxmocap-record",
                                        daemon=True)
        self._thread.start()

    def add(self, frame_index: int, time_s: float, *solved) -> None:
        """One solved frame: the source frame's number and time, and what the subclass's `_rows` reads; raises the
        error that stopped the writing."""
        if self.error is not None:
            raise self.error
        with self._adding:
            self._pending.append((frame_index, time_s, solved))

    def flush(self) -> list[Path]:
        """The frames added since the last flush appended to the journal and the files rewritten; the files."""
        with self._flushing:
            with self._adding:
                frames, self._pending = self._pending, []
            if not frames:
                return self.written
            done = self.frames.rows
            self.frames.append({"frame_index": np.asarray([f for f, _, _ in frames], np.int64),
                                "time_s": np.asarray([t for _, t, _ in frames], np.float64)})
            for name, arrays in self._rows([s for _, _, s in frames], list(self.columns)).items():
                if name not in self.columns:
                    self.columns[name] = Columns(self.journal / name)
                    for start in range(0, done, BACKFILL_ROWS):  # the frames before, without them
                        self._append(name, self._rows([self.nothing] * min(BACKFILL_ROWS, done - start),
                                                      [name])[name])
                self._append(name, arrays)
            self.written = self._write()
            return self.written

    def close(self, timeout: float) -> list[Path]:
        """The last frames written and the journal removed, within ``timeout`` seconds (`TimeoutError` after it:
        the files keep the frames of the last flush); the files written, or the error that stopped the writing."""
        self._stop.set()
        self._thread.join(timeout)
        if self._thread.is_alive():
            raise TimeoutError(f"--record: the last frames were not written within {timeout:.0f} s; "
                               f"{self.folder} keeps those written before")
        if self.error is not None:
            raise self.error
        shutil.rmtree(self.journal, ignore_errors=True)
        return self.written

    def _keep_writing(self, every_s: float) -> None:
        try:
            while not self._stop.wait(every_s):
                self.flush()
            self.flush()
        except BaseException as err:  # raised by the next `add` or by `close`
            self.error = err

    def _append(self, name: str, arrays: dict[str, np.ndarray]) -> None:
        self.columns[name].append(result_arrays(arrays, self.bools))

    def _npz(self, path: Path, name: str, more: dict[str, np.ndarray] | None = None) -> Path:
        """The file ``path`` of the columns ``name``, with the frames', `meta` and ``more``."""
        return write_npz(path, [self.columns[name], self.frames], result_arrays(self.meta | (more or {}), ()))

    def _rows(self, frames: list[tuple], names: list[str]) -> dict[str, dict[str, np.ndarray]]:
        """Each file's rows of ``frames`` (what `add` was given of each, after the frame's number and time), by
        the name of its columns: every name of ``names`` (those with earlier rows) and any new one."""
        raise NotImplementedError

    def _write(self) -> list[Path]:
        raise NotImplementedError


class Recorder(Recording):
    """A body session's frames (`add`: the source frame's number and time, each person's `Solved` and their 2D
    keypoints (67, 3), by identity): ``motion.npz`` of the person valid in most frames and
    ``people/<id>/motion.npz``; with ``world`` (the session's `LiveWorld`), once its floor is found, their world
    keys (`world.world_columns`, from each person's heels and toes kept in the journal beside their columns)."""

    bools = ("valid",)
    nothing = ({}, {})

    def __init__(self, folder, model: smplx_jax.BodyModel, model_sha256: str, lens: Lens, fps: float,
                 image_size: tuple[int, int], landmarks: str, every_s: float = FLUSH_SECONDS,
                 world: LiveWorld | None = None):
        self.model, self.lens, self.valid_frames, self.world, self.fps = model, lens, {}, world, fps
        pinhole = {} if lens[0] is None else {"focal_length": np.asarray(lens[0]),
                                              "principal_point": np.asarray(lens[1])}
        super().__init__(folder, {"fps": np.asarray(fps), "image_size": np.asarray(image_size),
                                  "model_sha256": np.asarray(model_sha256), "landmark_model": np.asarray(landmarks)}
                         | pinhole, every_s)

    def warm_up(self) -> None:
        """Compile what a flush's rows run (the joints and reprojection errors, one program a batch size of
        `fitting.BUCKETS`) before the first frame comes: compiled by the writing thread, they would take the
        solve's cores for seconds mid-session."""
        for size in fitting.BUCKETS:
            self._motion([None] * size, [None] * size)

    def _rows(self, frames, names):
        people = sorted({int(n.split(FEET)[0]) for n in names} | {i for solved, _ in frames for i in solved})
        rows = {}
        for i in people:
            motion, feet = self._motion([solved.get(i) for solved, _ in frames],
                                        [keypoints.get(i) for _, keypoints in frames])
            rows |= {str(i): motion, f"{i}{FEET}": {"feet": feet}}
        return rows

    def _motion(self, solved: list[Solved | None], keypoints: list[np.ndarray | None]
                ) -> tuple[dict[str, np.ndarray], np.ndarray]:
        """motion.npz's per-frame arrays of one person over some frames (None: not seen), and their heels and toes
        in the camera's frame ``(n, 4, 3)``."""
        bodies = Bodies.concatenate([self._row(s) for s in solved])
        keypoints = np.stack([np.zeros((67, 3), np.float32) if k is None else k for k in keypoints])
        arrays = motion_arrays(self.model, bodies, keypoints, self.lens)
        feet = body_joints(self.model, bodies.params)[:, FOOT_JOINTS].astype(np.float32)
        return {k: v for k, v in arrays.items() if k not in PINHOLE_SHAPES}, feet  # the lens: in `meta`

    def _row(self, solved: Solved | None) -> Bodies:
        """One frame of a person's `Bodies`: their solved body, or absent."""
        if solved is None:
            return Bodies.absent(1, self.model)
        return Bodies(jax.tree.map(lambda a: np.asarray(a)[None], solved.params),
                      np.asarray(solved.camera_scale)[None], np.asarray(solved.camera_trans)[None],
                      np.asarray(solved.valid)[None])

    def _append(self, name, arrays):
        super()._append(name, arrays)
        if "valid" in arrays:
            self.valid_frames[name] = self.valid_frames.get(name, 0) + int(arrays["valid"].sum())

    def _world(self, name: str) -> dict[str, np.ndarray]:
        """The world keys of person ``name``'s columns (none before the floor is found)."""
        if self.world is None:
            return {}
        columns = self.columns[name]
        motion = {k: columns.read(k) for k in ("global_orient", "transl", "betas", "valid")}
        return world_columns(self.model, self.world, motion | {"feet": self.columns[name + FEET].read("feet")},
                             self.fps)

    def _write(self):
        people = [n for n in self.columns if FEET not in n]
        main = max(people, key=lambda n: (self.valid_frames[n], -int(n)))  # the first seen of those tied
        world = {name: self._world(name) for name in people}
        return [self._npz(self.folder / "motion.npz", main, world[main])] + [
            self._npz(self.folder / "people" / name / "motion.npz", name, world[name]) for name in people]
