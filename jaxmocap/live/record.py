"""A live session's results kept frame by frame and written at the end as ``jaxmocap run`` writes them:
``motion.npz`` (the main person) and ``people/<id>/motion.npz``, with which source frame each row is."""

from pathlib import Path

import jax
import numpy as np

import smplx_jax
from jaxmocap.live.causal import Solved
from jaxmocap.motion import write_motion
from jaxmocap.pipeline.job import main_person
from jaxmocap.pipeline.records import Bodies
from jaxmocap.pipeline.stages import Lens, motion_arrays


class Recorder:
    """Collects each solved frame (`add`) and writes the motions (`write`)."""

    def __init__(self, model: smplx_jax.BodyModel, model_sha256: str, lens: Lens, fps: float,
                 image_size: tuple[int, int], landmarks: str):
        self.model, self.lens = model, lens
        self.meta = {"fps": np.asarray(fps), "image_size": np.asarray(image_size),
                     "model_sha256": np.asarray(model_sha256), "landmark_model": np.asarray(landmarks)}
        self.frames: list[tuple[int, float, dict[int, Solved], dict[int, np.ndarray]]] = []

    def add(self, frame: int, seconds: float, solved: dict[int, Solved], keypoints: dict[int, np.ndarray]) -> None:
        """One solved frame: the source frame's number and time, each person's body and 2D keypoints (67, 3)."""
        self.frames.append((frame, seconds, solved, keypoints))

    def motions(self) -> dict[int, dict[str, np.ndarray]]:
        """Each person's motion.npz arrays over the frames solved (not valid where they were not seen), plus
        ``frame_index (T,)`` and ``time_s (T,)``."""
        people = sorted({i for _, _, solved, _ in self.frames for i in solved})
        meta = self.meta | {"frame_index": np.asarray([f for f, *_ in self.frames], np.int64),
                            "time_s": np.asarray([t for _, t, *_ in self.frames], np.float64)}
        motions = {}
        for person in people:
            bodies = Bodies.concatenate([self._row(solved.get(person)) for _, _, solved, _ in self.frames])
            keypoints = np.stack([k.get(person, np.zeros((67, 3))) for *_, k in self.frames])
            motions[person] = motion_arrays(self.model, bodies, keypoints, self.lens) | meta
        return motions

    def _row(self, solved: Solved | None) -> Bodies:
        """One frame of a person's `Bodies`: their solved body, or absent."""
        if solved is None:
            return Bodies.absent(1, self.model)
        return Bodies(jax.tree.map(lambda a: np.asarray(a)[None], solved.params),
                      np.asarray(solved.camera_scale)[None], np.asarray(solved.camera_trans)[None],
                      np.asarray(solved.valid)[None])

    def write(self, folder: Path) -> list[Path]:
        """``folder/motion.npz`` (the main person: valid in most frames) and ``folder/people/<id>/motion.npz``;
        nothing without a frame."""
        motions = self.motions()
        main = main_person(motions)
        if main is None:
            return []
        folder = Path(folder)
        return [write_motion(folder / "motion.npz", motions[main])] + [
            write_motion(folder / "people" / str(i) / "motion.npz", m) for i, m in motions.items()]
