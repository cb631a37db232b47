"""``jaxmocap fit``: a folder of OpenPose JSON frames -> ``motion.npz`` of one tracked person."""

from __future__ import annotations

import math
import re
from pathlib import Path

import jax
import numpy as np

import smplx_jax
from jaxmocap.detect.openpose import read_openpose_json
from jaxmocap.errors import InputError
from jaxmocap.integrate import fitting
from jaxmocap.io import file_sha256
from jaxmocap.motion import motion_params, read_motion, write_motion
from jaxmocap.pipeline.records import Bodies
from jaxmocap.pipeline.stages import motion_arrays, one_shape, smoothed


def read_keypoint_folder(folder) -> tuple[list[Path], np.ndarray]:
    """The JSON files (sorted by name) and ``(T, 67, 3)`` keypoints of one tracked person: the most confident
    person in the first frame with anyone, then in each frame the person nearest the last one chosen."""
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"keypoint folder not found: {folder}")
    files = sorted(folder.glob("*.json"))
    if not files:
        raise InputError(f"no OpenPose .json files in {folder}")
    out = np.zeros((len(files), 67, 3), np.float32)
    last = None
    for i, path in enumerate(files):
        try:
            people = read_openpose_json(path)
        except ValueError as e:
            raise InputError(str(e)) from None
        if len(people) == 0:
            continue
        conf = np.where(np.isfinite(people[..., 2]), people[..., 2], 0.0)
        seen = conf > 0
        centres = np.array([p[s, :2].mean(0) if s.any() else np.full(2, np.inf) for p, s in zip(people, seen)])
        if last is None or not np.isfinite(last).all():
            pick = int(np.argmax(conf.sum(1)))
        else:
            pick = int(np.argmin(np.linalg.norm(centres - last, axis=1)))
        out[i] = people[pick]
        if seen[pick].any():
            last = centres[pick]
    return files, out


def keypoints_by_frame(folder) -> dict[int, np.ndarray]:
    """OpenPose JSON of one tracked person by frame number (from ``<stem>_<frame:012d>_keypoints.json`` names,
    else by sorted order); unseen keypoints are zeros."""
    files, keypoints = read_keypoint_folder(folder)
    numbers = [re.search(r"_(\d{12})_keypoints\.json$", f.name) for f in files]
    frames = [int(m.group(1)) for m in numbers] if all(numbers) else range(len(files))
    return dict(zip(frames, np.where(np.isfinite(keypoints), keypoints, 0.0)))


def infer_image_size(keypoints: np.ndarray) -> tuple[int, int]:
    """(width, height) when the JSON gives none: the smallest even size holding every keypoint, at least 2x2."""
    seen = keypoints[..., 2] > 0
    if not seen.any():
        return 2, 2
    xy = keypoints[seen][:, :2]
    return tuple(max(2, 2 * math.ceil((float(np.max(xy[:, i])) + 1) / 2)) for i in range(2))


def fit_keypoint_folder(keypoints_dir, out_dir, *, model_path=None, iterations: int | None = None, init=None,
                        smooth: bool = False, image_size=None, fps: float = 30.0, progress: bool = True) -> Path:
    files, keypoints = read_keypoint_folder(keypoints_dir)
    keypoints = np.where(np.isfinite(keypoints).all(-1, keepdims=True), keypoints, 0.0).astype(np.float32)
    iterations = fitting.ITERATIONS if iterations is None else iterations
    if iterations < 0:
        raise InputError(f"--iterations must be >= 0, got {iterations}")
    model_path = Path(model_path) if model_path else smplx_jax.default_model_path()
    model = smplx_jax.load_model(model_path)
    t = len(files)
    init_params = scale = trans = None
    if init is not None:
        arrays = read_motion(init)
        init_params = motion_params(arrays, model.num_expression)
        if arrays["betas"].shape != (t, model.num_betas):
            raise InputError(f"--init {init} has {arrays['betas'].shape[0]} frames x {arrays['betas'].shape[1]} "
                             f"betas; expected {t} x {model.num_betas}")
        scale, trans = arrays["camera_scale"], arrays["camera_trans"]
        if not (np.all(np.isfinite(scale)) and np.all(scale > 0)):
            scale = trans = None
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=t, unit="frame", desc="fit")
    try:
        result = fitting.fit(model, keypoints, init_params, scale, trans, iterations=iterations,
                             progress=bar.update if bar else None)
    except ValueError as e:
        raise InputError(str(e)) from None
    finally:
        if bar is not None:
            bar.close()
    bodies = Bodies(jax.tree.map(np.asarray, result.params), np.asarray(result.camera_scale),
                    np.asarray(result.camera_trans), np.asarray(result.valid))
    bodies = one_shape(model, bodies, keypoints, (None, None), fitting.FitConfig(), iterations)
    motion = motion_arrays(model, smoothed(model, bodies, keypoints) if smooth else bodies, keypoints)
    size = image_size if image_size else infer_image_size(keypoints)
    return write_motion(Path(out_dir) / "motion.npz", motion | {
        "fps": np.asarray(fps), "image_size": np.asarray(size), "model_sha256": np.asarray(file_sha256(model_path))})
