"""``jaxmocap run``: video (or images, or a webcam) in; whole-body SMPL-X motion, keypoints, overlay and exports out.

The embedded default path (no licensed file): detector (2D keypoints and metric 3D landmarks; left and right put
back where it exchanged them, hands lost for a moment interpolated) -> IK of body and hands from the 3D landmarks
(hands pasted under the body's kinematics) -> optimisation integration on the 2D keypoints through a pinhole
camera -> temporal smoothing. With FrankMocap's converted weights: body and hand regressors on the detector's
boxes -> copy-and-paste -> optionally the same fit. Frames go in chunks; each finished chunk is stored, so an
interrupted run resumes where it stopped and ends with the same ``motion.npz`` as an uninterrupted one (the
detector starts afresh at every chunk, in both cases).
"""

import dataclasses
import re
import time
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import smplx_jax
from jaxmocap.detect import Detector
from jaxmocap.detect.openpose import json_name, write_openpose_json
from jaxmocap.errors import InputError
from jaxmocap.export.frankmocap import write_frankmocap_pkls
from jaxmocap.integrate import FitConfig, body_from_blazepose, fit, fitted_motion, hand_into_body
from jaxmocap.integrate.camera import default_focal_length
from jaxmocap.integrate.fitting import params_from_full_pose
from jaxmocap.integrate.folder import read_keypoint_folder
from jaxmocap.io import file_sha256
from jaxmocap.frame_source import open_media
from jaxmocap.motion import write_motion
from jaxmocap.pipeline.chunks import ChunkStore
from jaxmocap.pipeline.observe import Observations, observe, repaired
from jaxmocap.pipeline.outputs import EXPORT_FILES, write_exports, write_overlay
from jaxmocap.pipeline.regress import Regression, solve_regressors

SETTINGS_VERSION = 3


@dataclass
class RunReport:
    """What a run wrote and how long each stage took (seconds)."""

    motion: Path
    frames: int
    valid: int
    seconds: dict = field(default_factory=lambda: defaultdict(float))
    written: list = field(default_factory=list)


def initial_bodies(model, obs: Observations) -> smplx_jax.SMPLXParams:
    """The fit's start for each frame: IK of the body to BlazePose's world landmarks, then of each hand to its
    landmarks with the body fixed (batched `SMPLXParams`)."""
    theta, betas, _, _ = body_from_blazepose(model, obs.body_world)
    for side, name in enumerate(("left", "right")):
        conf = np.repeat(obs.hands_conf[:, side:side + 1] > 0, 21, axis=1).astype(np.float32)
        theta, betas, _, _ = hand_into_body(model, name, obs.hands_world[:, side], theta, betas, conf=conf)
    return params_from_full_pose(jnp.asarray(theta), jnp.asarray(betas), model.num_expression)


# The fit from the IK start: the start already holds BlazePose's 3D (depth, twists) that the 2D keypoints do not see,
# so the prior keeps the fit near it (0.1 m/rad; the generic fit's 0.02 lets depth drift: 3D error +10 mm on real
# footage, `bench/accuracy.py`).
FIT_FROM_IK = FitConfig(prior_body=0.1, prior_finger_hinge=0.05, prior_finger_range=0.2)


def fitted_bodies(model, obs: Observations, init: smplx_jax.SMPLXParams, image_size, iterations: int = 20,
                  focal_length: float | None = None):
    """The fit of each frame to its 2D keypoints from the IK start (`FitResult`; before temporal smoothing), through
    a pinhole camera of ``focal_length`` pixels (default `default_focal_length`) centred on the image of
    ``image_size`` (width, height)."""
    focal_length, principal_point = _lens(image_size, focal_length)
    return fit(model, obs.keypoints, init=init, focal_length=focal_length, principal_point=principal_point,
               iterations=iterations, config=FIT_FROM_IK)


def _lens(image_size, focal_length=None):
    return focal_length or default_focal_length(image_size), np.asarray(image_size, np.float32) / 2


def _solve(model, obs, image_size, iterations, focal_length, seconds):
    """IK from the 3D landmarks, then the fit to the 2D keypoints, for one chunk of frames."""
    t0 = time.perf_counter()
    init = jax.block_until_ready(initial_bodies(model, obs))
    t1 = time.perf_counter()
    result = fitted_bodies(model, obs, init, image_size, iterations, focal_length)
    jax.block_until_ready(result)
    seconds["ik"] += t1 - t0
    seconds["fit"] += time.perf_counter() - t1
    arrays = {k: np.asarray(v) for k, v in vars(result.params).items()}
    return arrays | {"camera_scale": np.asarray(result.camera_scale), "camera_trans": np.asarray(result.camera_trans),
                     "valid": obs.found & np.asarray(result.valid)}


def _keypoints_by_frame(folder) -> dict[int, np.ndarray]:
    """OpenPose JSON of one tracked person by frame number (from ``<stem>_<frame:012d>_keypoints.json`` names,
    else by sorted order)."""
    files, keypoints = read_keypoint_folder(folder)
    numbers = [re.search(r"_(\d{12})_keypoints\.json$", f.name) for f in files]
    frames = [int(m.group(1)) for m in numbers] if all(numbers) else range(len(files))
    return dict(zip(frames, np.where(np.isfinite(keypoints), keypoints, 0.0)))


def run(source, out_dir, *, model_path=None, weights=None, integration: str = "optimize", keypoints_dir=None,
        start: int = 0, end: int | None = None, stride: int = 1, chunk_size: int = 128, iterations: int = 20,
        focal_length: float | None = None, smooth: bool = True,
        overlay: bool = True, exports: tuple[str, ...] = (), progress: bool = True, hand_boxes: str = "keypoints",
        frankmocap_pkl: bool = False) -> RunReport:
    """Run over ``source`` and write ``out_dir/motion.npz`` (DESIGN 2.3), the detections as OpenPose JSON in
    ``out_dir/keypoints/``, ``out_dir/overlay.mp4`` and the requested exports. Without ``weights`` the embedded
    default path; with ``weights`` (from ``convert-frankmocap``) FrankMocap's regressors (for ``integration="eft"``
    the body regressor fine-tuned per frame on the 2D keypoints), copy-and-paste and, for
    ``integration="optimize"``, the fit. ``keypoints_dir``: OpenPose JSON (e.g. from OpenPose itself) to fit to
    instead of the detector's 2D keypoints. ``hand_boxes="body"`` (with ``weights``): hand boxes from the body
    regressor's projected hands and the detector's pose alone (FrankMocap's fast mode). ``frankmocap_pkl``: also
    FrankMocap's per-frame prediction pickles in ``out_dir/mocap/``. ``focal_length``: the camera's, in pixels
    (default `default_focal_length`: a phone's main camera)."""
    from tqdm import tqdm

    if integration not in ("optimize", "copy-paste", "eft"):
        raise InputError(f"unknown integration {integration!r} (optimize, copy-paste or eft)")
    if integration in ("copy-paste", "eft") and weights is None:
        raise InputError(f"--integration {integration} needs --weights (the regressors); the default path optimizes")
    if focal_length is not None and not focal_length > 0:
        raise InputError(f"--focal-length must be positive, got {focal_length}")
    if hand_boxes not in ("keypoints", "body"):
        raise InputError(f"unknown hand boxes {hand_boxes!r} (keypoints or body)")
    if hand_boxes == "body" and weights is None:
        raise InputError("--hand-boxes body needs --weights (the body regressor gives the hand boxes)")
    unknown = sorted(set(exports) - set(EXPORT_FILES))
    if unknown:
        raise InputError(f"unknown export format(s) {', '.join(unknown)} (known: {', '.join(EXPORT_FILES)})")
    out_dir = Path(out_dir)
    (out_dir / "keypoints").mkdir(parents=True, exist_ok=True)
    model_path = Path(model_path) if model_path else smplx_jax.default_model_path()
    model = smplx_jax.load_model(model_path)
    model_sha = file_sha256(model_path)
    regression = Regression.load(weights, model, hand_boxes == "body") if weights is not None else None
    given = _keypoints_by_frame(keypoints_dir) if keypoints_dir is not None else None
    media, frames = open_media(source, start, end, stride)
    still = media.kind in ("image", "images")
    source_id = str(Path(source).resolve()) if not str(source).isdigit() else str(source)
    store = ChunkStore(out_dir, dict(version=SETTINGS_VERSION, source=source_id, start=start, end=end, stride=stride,
                                     chunk=chunk_size, iterations=iterations, focal_length=focal_length,
                                     model=model_sha,
                                     weights=weights and file_sha256(Path(weights) / "regressors.json"),
                                     integration=integration, hand_boxes=hand_boxes,
                                     keypoints=keypoints_dir and str(Path(keypoints_dir).resolve())))
    detector = Detector(static_image_mode=still, hands=hand_boxes == "keypoints")
    report = RunReport(out_dir / "motion.npz", 0, 0)
    seconds = report.seconds
    chunks, frame_ids = [], []
    bar = tqdm(total=media.frame_count, unit="frame", desc="run", disable=not progress)
    iterator = iter(frames)
    index = 0
    while True:
        t0 = time.perf_counter()
        batch = [item for _, item in zip(range(chunk_size), iterator)]
        seconds["decode"] += time.perf_counter() - t0
        if not batch:
            break
        ids = [i for i, _ in batch]
        stored = store.load(index)
        if stored is None or not np.array_equal(stored["frame_index"], ids):
            t0 = time.perf_counter()
            detector.reset()
            obs = observe(detector, [frame for _, frame in batch])
            if not still:
                obs = repaired(obs, media.fps)
            if given is not None:
                obs = dataclasses.replace(obs, keypoints=np.stack([given.get(i, np.zeros((67, 3))) for i in ids]))
            seconds["detect"] += time.perf_counter() - t0
            if regression is None:
                solved = _solve(model, obs, media.size, iterations, focal_length, seconds)
            else:
                t0 = time.perf_counter()
                solved = solve_regressors(model, regression, [frame for _, frame in batch], obs, integration,
                                          iterations)
                seconds["regress+integrate"] += time.perf_counter() - t0
            stored = {"body_box": obs.body_box, "hand_boxes": obs.hand_boxes} | solved | {
                "keypoints_2d": obs.keypoints, "frame_index": np.asarray(ids)}
            store.save(index, stored)
            for n, frame_id in enumerate(ids):
                name = json_name(media.stems[len(frame_ids) + n], None) if still else json_name(media.stem, frame_id)
                write_openpose_json(out_dir / "keypoints" / name, obs.keypoints[n][None] if obs.found[n] else
                                    np.zeros((0, 67, 3)))
        chunks.append(stored)
        frame_ids.extend(ids)
        index += 1
        bar.update(len(batch))
        bar.set_postfix(fps=f"{len(frame_ids) / max(sum(seconds.values()), 1e-9):.1f}")
    bar.close()

    t0 = time.perf_counter()
    lens = (None, None) if regression is not None else _lens(media.size, focal_length)  # as the chunks were fitted
    motion = _assemble(model, chunks, smooth, lens)
    motion |= {"fps": np.asarray(media.fps), "image_size": np.asarray(media.size),
               "model_sha256": np.asarray(model_sha)}
    write_motion(report.motion, motion)
    seconds["smooth+write"] += time.perf_counter() - t0
    report.frames, report.valid = len(frame_ids), int(motion["valid"].sum())
    report.written.append(report.motion)
    if frankmocap_pkl:
        boxes = [np.concatenate([c[k] for c in chunks]) for k in ("body_box", "hand_boxes")]
        report.written.extend(write_frankmocap_pkls(out_dir, model, motion, *boxes,
                                                    _frame_images(media, out_dir, frame_ids)))
    if overlay:
        t0 = time.perf_counter()
        report.written.append(write_overlay(out_dir / "overlay.mp4", model, motion, source, start, end, stride,
                                            progress=progress))
        seconds["overlay"] += time.perf_counter() - t0
    if exports:
        t0 = time.perf_counter()
        report.written.extend(write_exports(out_dir, model, motion, exports))
        seconds["exports"] += time.perf_counter() - t0
    store.clear()
    return report


def _frame_images(media, out_dir: Path, frame_ids) -> list[Path]:
    """Each frame's image as FrankMocap names it: the image file, else ``frames/<frame:05d>.jpg`` (a webcam's
    ``frames/scene_<frame:05d>.jpg``), which FrankMocap writes only with ``--save_frame``."""
    if media.paths:
        return list(media.paths)
    prefix = "scene_" if media.kind == "webcam" else ""
    return [out_dir / "frames" / f"{prefix}{i:05d}.jpg" for i in frame_ids]


def _assemble(model, chunks, smooth, lens):
    """The whole sequence from its chunks, smoothed over all frames; ``lens``: the pinhole camera the chunks were
    fitted through, or ``(None, None)``."""
    cat = {k: np.concatenate([c[k] for c in chunks]) for k in chunks[0] if k != "frame_index"}
    params = smplx_jax.SMPLXParams(**{k: jnp.asarray(cat[k]) for k in (
        "global_orient", "body_pose", "left_hand_pose", "right_hand_pose", "jaw_pose", "leye_pose", "reye_pose",
        "betas", "expression", "transl")})
    return fitted_motion(model, params, cat["camera_scale"], cat["camera_trans"], cat["valid"], cat["keypoints_2d"],
                         smooth, *lens)
