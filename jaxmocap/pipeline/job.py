"""``jaxmocap run``: video (or images, or a webcam) in; whole-body SMPL-X motion, keypoints, overlay and exports out.

`run` reads as its stages (`jaxmocap.pipeline.stages`). The embedded default path (no licensed file): the detector's
2D keypoints and 3D landmarks -> IK of body and hands from the landmarks -> the fit to the 2D keypoints through a
pinhole camera. With FrankMocap's converted weights: body and hand regressors on the detector's boxes ->
copy-and-paste -> optionally the same fit. ``--mode body`` runs no hand model (the detector without hands, no hand
IK, no hand regressor): the hands stay flat. Frames go in chunks; each finished chunk is stored, so an interrupted
run resumes where it stopped and ends with the same ``motion.npz`` as an uninterrupted one (each chunk stores what
the detector and the identities carry on to the next). Then over the whole sequence, for each person: the start (IK,
in windows placed by frame number), the whole clip as one fit -> ``motion.npz`` -> the outputs. ``--mode hands`` is
`hands_job`'s (`entry.run` dispatches).
"""

import dataclasses
import functools
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

import smplx_jax
from jaxmocap.detect import Detector
from jaxmocap.detect.camera_turns import CameraTurns, camera_motion
from jaxmocap.detect.detector import search_interval
from jaxmocap.detect.identities import IdentityTracker
from jaxmocap.detect.models import available_landmarks
from jaxmocap.detect.verticals import AGREE_RAD, images_vertical
from jaxmocap.frame_source import Media, open_media, sample_frames
from jaxmocap.integrate.ground import main_person, standing, world_arrays
from jaxmocap.motion import write_motion
from jaxmocap.pipeline.chunks import ChunkStore, stored_or_solved
from jaxmocap.pipeline.config import RunConfig, chunk_key
from jaxmocap.pipeline.fit_folder import keypoints_by_frame
from jaxmocap.pipeline.merge_tracks import merge_split_tracks
from jaxmocap.pipeline.observe import HAND_GAP_SECONDS, Observations, fill_hand_gaps
from jaxmocap.pipeline.outputs import write_keypoints, write_outputs
from jaxmocap.pipeline.regress import Regression, regressed_bodies
from jaxmocap.pipeline.report import RunReport
from jaxmocap.pipeline.stage_clock import StageClock
from jaxmocap.pipeline.stages import (
    Lens,
    lens_of,
    median_shape,
    motion_arrays,
    observations,
    placed_bodies,
)
from jaxmocap.pipeline.tracks import Bodies, Chunk, Track
from jaxmocap.pipeline.whole_clip import fitted_track, with_start
from jaxmocap.result_files import file_sha256

Observer = Callable[[Chunk, dict[int, Observations]], None]
SETTINGS_VERSION = 11  # of the stored chunks: bump when what a chunk holds changes


@dataclass(frozen=True)
class Inputs:
    """A run's inputs, opened once: the body model, the regressors (or None), the OpenPose keypoints given instead
    of the detector's (or None), the media and its frames, the pinhole camera fitted through (or none), and the
    BlazePose landmark model the detector runs (`available_landmarks` of the one asked for)."""

    model: smplx_jax.BodyModel
    model_sha256: str
    regression: Regression | None
    given_keypoints: dict[int, np.ndarray] | None
    media: Media
    frames: Iterator[tuple[int, np.ndarray]]
    lens: Lens
    landmarks: str

    @classmethod
    def open(cls, config: RunConfig) -> "Inputs":
        model_path = smplx_jax.model_path(config.model)
        model = smplx_jax.load_model(model_path)
        regression = None if config.weights is None else Regression.load(
            config.weights, model, config.hand_boxes if config.mode == "whole" else None)
        given = None if config.keypoints is None else keypoints_by_frame(config.keypoints)
        media, frames = open_media(config.source, config.start, config.end, config.stride)
        clip_fit = regression is None or config.integration == "optimize"  # (`_clip_fitted`): a pinhole camera
        lens = lens_of(media.size, config.focal_length) if clip_fit else (None, None)
        landmarks = available_landmarks(config.landmarks)
        return cls(model, file_sha256(model_path), regression, given, media, frames, lens, landmarks)


def run_bodies(config: RunConfig, out_dir, observed: Observer | None = None) -> RunReport:
    """Run ``config`` (``--mode whole`` or ``body``) and write ``out_dir/motion.npz`` (the main person;
    docs/formats.md), each person's ``out_dir/people/<id>/motion.npz``, the detections as OpenPose JSON in
    ``out_dir/keypoints/``, and the outputs ``config`` asks for (`write_outputs`).
    ``observed(chunk, people)``, if given, sees each chunk solved (not those restored from a stored run) with its
    people's `Observations` by identity, as the fit took them (`bench/accuracy.py` scores the stages from them)."""
    if config.mode == "hands":
        raise ValueError("config: --mode hands is hands_job.run_hands's (pipeline.run dispatches)")
    out_dir = Path(out_dir)
    (out_dir / "keypoints").mkdir(parents=True, exist_ok=True)
    inputs = Inputs.open(config)
    config = dataclasses.replace(config, landmarks=inputs.landmarks)  # what the chunks are made with
    store = ChunkStore(out_dir, chunk_key(config, inputs.model_sha256) | {"version": SETTINGS_VERSION})
    clock = StageClock()
    chunks = list(solved_chunks(config, inputs, store, out_dir, clock, observed))
    video = inputs.media.kind in ("video", "webcam")
    tracks = merge_split_tracks(whole_tracks(chunks, inputs.model), inputs.media.fps if video else None,
                                config.max_people)
    if inputs.regression is None:
        with clock("ik"):  # each frame's start, in windows placed by frame number (not by chunk)
            tracks = {i: with_start(inputs.model, t, inputs.lens) for i, t in tracks.items()}
    fit, rate = _clip_fitted(config, inputs), inputs.media.fps if video and config.smooth else None
    turns = np.concatenate([c.scene_from_camera for c in chunks]) if _turns_measured(config, inputs) else None
    with clock("fit"):  # the whole clip (or the regressors' shape)

        def person_bodies(track):
            if fit:  # the whole clip as one fit
                return fitted_track(inputs.model, track, inputs.lens, rate, scene_from_camera=turns)
            return median_shape(track.bodies)  # as regressed

        tracks = {i: dataclasses.replace(t, bodies=person_bodies(t)) for i, t in tracks.items()}
    ground, main = None, main_person({i: t.bodies.valid for i, t in tracks.items()})
    if video and inputs.lens[0] is not None:  # the scene's floor, everyone on it
        with clock("ground"):
            ground = standing(inputs.model, _people(tracks), inputs.media.fps, main,
                              functools.partial(_scene_up, config, inputs, chunks), turns)
            if ground and fit and rate:  # the clip fit refitted standing on it
                tracks = {i: dataclasses.replace(t, bodies=fitted_track(inputs.model, t, inputs.lens, rate,
                                                                        ground=ground.clip_ground(i),
                                                                        scene_from_camera=turns))
                          for i, t in tracks.items()}
    with clock("write"):
        meta = {"fps": np.asarray(inputs.media.fps), "image_size": np.asarray(inputs.media.size),
                "model_sha256": np.asarray(inputs.model_sha256), "landmark_model": np.asarray(inputs.landmarks)}
        motions = {i: motion_arrays(inputs.model, t.bodies, t.keypoints_2d, inputs.lens) | meta
                   for i, t in tracks.items()}
        if ground:  # the scene's world frame, on the floor
            world = world_arrays(inputs.model, _people(tracks), main, ground, turns)
            motions = {i: m | world[i] for i, m in motions.items()}
        frames = sum(len(c.frame_index) for c in chunks)
        motion = motions[main] if motions else motion_arrays(
            inputs.model, Bodies.absent(frames, inputs.model), np.zeros((frames, 67, 3)), inputs.lens) | meta
        written = [write_motion(out_dir / "motion.npz", motion)]
        written += [write_motion(out_dir / "people" / str(i) / "motion.npz", m) for i, m in motions.items()]
    written += write_outputs(config, out_dir, inputs.model, inputs.media, motions, main, tracks, chunks, clock)
    store.clear()
    return RunReport(written[0], frames, int(motion["valid"].sum()), dict(clock.seconds), written, sorted(motions),
                     inputs.landmarks, None if turns is None else camera_motion(
                         turns, np.concatenate([c.background_px for c in chunks]), max(inputs.media.size)))


def _people(tracks: dict[int, Track]) -> dict[int, tuple[smplx_jax.SMPLXParams, np.ndarray]]:
    """Each person's bodies and where they are valid (`integrate.ground`'s ``people``)."""
    return {i: (t.bodies.params, t.bodies.valid) for i, t in tracks.items()}


SCENE_FRAMES = 5  # frames of a video whose straight edges show the scene's vertical (a static camera's: the same)


def _scene_up(config: RunConfig, inputs: Inputs, chunks: list[Chunk], near: np.ndarray) -> np.ndarray | None:
    """The scene's vertical near ``near`` (`verticals.scene_vertical`; the scene's axes) from `SCENE_FRAMES` frames
    spread over those the run read, through the focal length its edges show unless the user gave one; None for a
    webcam (its frames are gone). A camera that turns between them by more than an edge's agreement
    (`verticals.AGREE_RAD`) sees each frame's edges from its own axes: then each frame's vertical, turned into the
    scene's, their mean."""
    if inputs.media.kind != "video":
        return None
    read = np.concatenate([c.frame_index for c in chunks])
    picked = np.linspace(0, len(read) - 1, SCENE_FRAMES).astype(int)
    images = sample_frames(config.source, read[picked].tolist())
    turn = Rotation.from_rotvec(np.concatenate([c.scene_from_camera for c in chunks])[picked]).as_matrix()
    if np.all(np.arccos(np.clip((np.trace(turn[0].T @ turn, axis1=1, axis2=2) - 1) / 2, -1, 1)) < AGREE_RAD):
        groups = [(images, turn[0])]
    else:
        groups = [([image], r) for image, r in zip(images, turn)]
    found = [r @ v for images, r in groups if (v := images_vertical(
        images, inputs.lens, r.T @ near, max(inputs.media.size), config.focal_length is not None)) is not None]
    return np.mean(found, 0) / np.linalg.norm(np.mean(found, 0)) if found else None


def _clip_fitted(config: RunConfig, inputs: Inputs) -> bool:
    """Whether the run's motion is the clip fit (`fitted_track`): the embedded default, and the regressors' bodies
    with ``--integration optimize``; copy-and-paste and EFT keep the regressors' bodies as they are."""
    return inputs.regression is None or config.integration == "optimize"


def whole_tracks(chunks: list[Chunk], model: smplx_jax.BodyModel) -> dict[int, Track]:
    """Each person over all frames, by identity, from the chunks (not valid where absent)."""
    people = sorted({i for c in chunks for i in c.people})
    return {i: Track.concatenate([c.people.get(i) or Track.absent(len(c.frame_index), model) for c in chunks])
            for i in people}


def solved_chunks(config: RunConfig, inputs: Inputs, store: ChunkStore, out_dir: Path, clock: StageClock,
                  observed: Observer | None = None) -> Iterator[Chunk]:
    """Each chunk of frames, from the store if it holds it, else through the per-chunk stages (`solve_chunk`),
    then stored and its detections written as OpenPose JSON. The detector's tracks, the identities and each
    person's last repaired keypoints carry on from chunk to chunk (in a video), restored from a stored chunk's."""
    from tqdm import tqdm

    still = inputs.media.kind in ("image", "images")
    detector = Detector(static_image_mode=still, hands=config.mode == "whole" and config.hand_boxes == "keypoints",
                        max_people=1 if config.keypoints else config.max_people,
                        redetect_every=search_interval(inputs.media.fps), landmarks=inputs.landmarks)
    tracker = None if still else IdentityTracker()
    camera = CameraTurns(inputs.lens) if _turns_measured(config, inputs) else None

    def solve(ids, frames, previous):
        sides = {} if previous is None else _part(previous.tracking, "sides/")
        return solve_chunk(config, inputs, detector, tracker, camera, ids, frames, clock, observed,
                           {int(i): k for i, k in sides.items()})

    with tqdm(total=inputs.media.frame_count, unit="frame", desc="run", disable=not config.progress) as bar:
        yield from stored_or_solved(
            inputs.frames, config.chunk_size, store, clock, solve,
            lambda chunk, first: write_keypoints(out_dir / "keypoints", inputs.media, chunk, first),
            lambda chunk: _restore(chunk.tracking, detector, tracker, camera), bar)


def solve_chunk(config: RunConfig, inputs: Inputs, detector: Detector, tracker: IdentityTracker | None,
                camera: CameraTurns | None, ids: np.ndarray, frames: list[np.ndarray], clock: StageClock,
                observed: Observer | None = None, previous: dict[int, np.ndarray] | None = None) -> Chunk:
    """One chunk through detection and the camera's turns (``camera``; None: a static camera), then for each
    person the regressors (if any: without them the clip fit's start comes over the whole track, `with_start`);
    ``previous``: each identity's repaired keypoints in the frame before the chunk."""
    with clock("detect"):
        given = None if inputs.given_keypoints is None else np.stack(
            [inputs.given_keypoints.get(int(i), np.zeros((67, 3))) for i in ids])
        video = inputs.media.kind in ("video", "webcam")
        people, last = observations(detector, tracker, frames, inputs.media.fps if video else None, given, previous)
    turns, background = np.zeros((len(frames), 3), np.float32), np.full(len(frames), np.nan, np.float32)
    if camera is not None:
        with clock("camera"):
            turns, background = camera.turns(frames, [np.stack([o.body_box[k] for o in people.values()])
                                                      if people else np.zeros((0, 4)) for k in range(len(frames))])
    tracks = {}
    for person_id, obs in people.items():
        if inputs.regression is None:  # the start comes over the whole track (`with_start`)
            bodies, hand_boxes = Bodies.absent(len(frames), inputs.model), obs.hand_boxes
        else:
            with clock("regress"):
                boxed = fill_hand_gaps(obs, round(HAND_GAP_SECONDS * inputs.media.fps)) if video else obs
                bodies, hand_boxes = regressed_bodies(inputs.model, inputs.regression, frames, boxed,
                                                      config.integration)
                if _clip_fitted(config, inputs):  # the clip fit's start
                    bodies = placed_bodies(inputs.model, bodies.params, obs.keypoints, inputs.lens, bodies.valid)
        tracks[person_id] = Track(obs.keypoints, obs.body_box, hand_boxes, obs.found, obs.body_world,
                                  obs.hands_world, obs.hands_conf, bodies)
    chunk = Chunk(ids, tracks, _tracking(detector, tracker, camera) | {f"sides/{i}": k for i, k in last.items()},
                  turns, background)
    if observed is not None:
        observed(chunk, people)
    return chunk


def _tracking(detector: Detector, tracker: IdentityTracker | None, camera: CameraTurns | None
              ) -> dict[str, np.ndarray]:
    """What the detector, the identities and the camera's turns carry from one chunk to the next, as arrays."""
    identities = {} if tracker is None else {f"identities/{k}": v for k, v in tracker.state().items()}
    turns = {} if camera is None else {f"camera/{k}": v for k, v in camera.state().items()}
    return {f"detector/{k}": v for k, v in detector.state().items()} | identities | turns


def _part(tracking: dict[str, np.ndarray], prefix: str) -> dict[str, np.ndarray]:
    return {k.split("/", 1)[1]: v for k, v in tracking.items() if k.startswith(prefix)}


def _restore(tracking: dict[str, np.ndarray], detector: Detector, tracker: IdentityTracker | None,
             camera: CameraTurns | None) -> None:
    detector.restore(_part(tracking, "detector/"))
    if tracker is not None:
        tracker.restore(_part(tracking, "identities/"))
    if camera is not None:
        camera.restore(_part(tracking, "camera/"))


def _turns_measured(config: RunConfig, inputs: Inputs) -> bool:
    """Whether the run measures the camera's turns: a video (or webcam) through a pinhole camera, unless
    ``--camera static``."""
    return config.camera == "turns" and inputs.media.kind in ("video", "webcam") and inputs.lens[0] is not None

