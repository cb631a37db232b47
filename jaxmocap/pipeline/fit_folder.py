"""``jaxmocap fit``: a folder of OpenPose JSON frames -> ``motion.npz`` of one tracked person."""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

import smplx_jax
from jaxmocap.detect.openpose import read_openpose_json
from jaxmocap.errors import InputError
from jaxmocap.integrate import ClipConfig
from jaxmocap.integrate.fitting import params_from_full_pose
from jaxmocap.integrate.keypoint_start import facing_pose
from jaxmocap.motion import motion_params, read_motion, write_motion
from jaxmocap.pipeline.stages import Lens, lens_of, motion_arrays, placed_bodies
from jaxmocap.pipeline.tracks import Bodies
from jaxmocap.pipeline.whole_clip import FittedClip, blocks, fitted_clip
from jaxmocap.result_files import file_sha256


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
                        smooth: bool = True, image_size=None, focal_length: float | None = None, fps: float = 30.0,
                        progress: bool = True) -> Path:
    """Fit the person of an OpenPose JSON folder (`read_keypoint_folder`) as one clip (`whole_clip.fitted_clip`,
    the 2D keypoints alone) through a pinhole camera of ``focal_length`` pixels (default `lens_of`'s) centred on
    the image of ``image_size`` (default `infer_image_size`) and write ``out_dir/motion.npz``. Each frame starts
    from ``init``'s pose (a motion.npz of the same frames) or `keypoint_start.facing_pose`, placed on its
    keypoints; ``smooth`` False: the frames are unrelated images (no motion between them); ``iterations`` caps each
    window's Levenberg-Marquardt steps (default `ClipConfig`'s)."""
    files, keypoints = read_keypoint_folder(keypoints_dir)
    keypoints = np.where(np.isfinite(keypoints).all(-1, keepdims=True), keypoints, 0.0).astype(np.float32)
    config = ClipConfig() if iterations is None else ClipConfig(iterations=iterations)
    if config.iterations < 0:
        raise InputError(f"--iterations must be >= 0, got {config.iterations}")
    if focal_length is not None and not focal_length > 0:
        raise InputError(f"--focal-length must be positive, got {focal_length}")
    if image_size is not None and min(image_size) < 1:
        raise InputError(f"--image-size must be positive, got {image_size[0]} {image_size[1]}")
    model_path = smplx_jax.model_path(model_path)
    model = smplx_jax.load_model(model_path)
    t = len(files)
    params = None
    if init is not None:
        arrays = read_motion(init)
        if arrays["betas"].shape != (t, model.num_betas):
            raise InputError(f"--init {init} has {arrays['betas'].shape[0]} frames x {arrays['betas'].shape[1]} "
                             f"betas; expected {t} x {model.num_betas}")
        params = motion_params(arrays, model.num_expression)
    size = tuple(image_size) if image_size else infer_image_size(keypoints)
    lens = lens_of(size, focal_length)
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=t, unit="frame", desc="fit")
    try:
        bodies = fitted_keypoints(model, keypoints, lens, fps if smooth else None, params, config,
                                  bar.update if bar else None).bodies
    finally:
        if bar is not None:
            bar.close()
    motion = motion_arrays(model, bodies, keypoints, lens)
    return write_motion(Path(out_dir) / "motion.npz", motion | {
        "fps": np.asarray(fps), "image_size": np.asarray(size), "model_sha256": np.asarray(file_sha256(model_path))})


def fitted_keypoints(model: smplx_jax.BodyModel, keypoints: Float[ArrayLike, "T 67 3"], lens: Lens,
                     fps: float | None, init: smplx_jax.SMPLXParams | None = None, config: ClipConfig = ClipConfig(),
                     progress: Callable[[int], object] | None = None) -> FittedClip:
    """One person's 2D keypoints ``(T, 67, 3)`` fitted as one clip (`whole_clip.fitted_clip`, no 3D observation)
    through the pinhole ``lens``, each frame from ``init``'s pose (T leading) or `keypoint_start.facing_pose`,
    placed on its keypoints (`stages.placed_bodies`); fitted where any keypoint is seen."""
    keypoints = np.asarray(keypoints, np.float32)
    init = facing_params(model, keypoints) if init is None else init
    found = np.any(keypoints[..., 2] > 0, -1)
    start = Bodies.concatenate([  # placed block by block: memory flat however long the clip
        jax.tree.map(lambda a: np.asarray(a)[:kept], placed_bodies(
            model, jax.tree.map(lambda a: np.asarray(a)[frames], init), keypoints[frames], lens, found[frames]))
        for frames, kept in blocks(len(keypoints))])
    return fitted_clip(model, keypoints, start.params, found, lens, fps, config=config, progress=progress)


def facing_params(model: smplx_jax.BodyModel, keypoints: Float[ArrayLike, "T 67 3"]) -> smplx_jax.SMPLXParams:
    """Each frame's `keypoint_start.facing_pose` (T leading; the mean shape, no translation)."""
    return params_from_full_pose(_facing_poses(np.asarray(keypoints, np.float32)),
                                 jnp.zeros((len(keypoints), model.num_betas)), model.num_expression)


_facing_poses = jax.jit(jax.vmap(facing_pose))
