"""``jaxmocap run --mode hands``: hands on their own, no body needed (FrankMocap's hand demo: close-ups, ego-centric
video). Palms over the whole frame (`detect.hand_tracker`), up to ``max_hands``, tracked in a video, each with its
side; per hand IK from its 21 world landmarks and the optimistix fit to its 21 keypoints (`integrate.hand_fit`), or
with FrankMocap's weights the hand regressor on the hands' boxes, then the same fit. In chunks, resumable like the
whole-body run; then in a video each side's frames as one fit with the motion between them (`integrate.hand_clip`,
in windows placed by frame number) -> ``hands.npz`` (the left and the right hand: in each frame the likeliest of
each side) -> OpenPose JSON of the hands, overlay, glTF.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

import smplx_jax
from jaxmocap.compile_cache import disk_jit
from jaxmocap.detect.hand_json import hands_openpose
from jaxmocap.detect.hand_tracker import HandTracker
from jaxmocap.detect.openpose import json_name, write_openpose_json
from jaxmocap.errors import InputError
from jaxmocap.frame_source import open_media
from jaxmocap.hand_motion import HAND_SHAPES, hand_meshes, write_hands
from jaxmocap.integrate.hand_clip import fit_hand_clip, hand_clip_start
from jaxmocap.integrate.hand_fit import fit_hands, hand_keypoint_model
from jaxmocap.overlay import OverlayWriter, Posed
from jaxmocap.pipeline.chunks import ChunkStore, stored_or_solved
from jaxmocap.pipeline.config import RunConfig, chunk_key
from jaxmocap.pipeline.report import RunReport
from jaxmocap.pipeline.stage_clock import StageClock
from jaxmocap.pipeline.stages import lens_of
from jaxmocap.pipeline.whole_clip import hand_bone_directions, part_noise_px, window_spans
from jaxmocap.result_files import file_sha256
from smplx_jax import SIDES
from smplx_jax.atomic_files import atomic_path

SETTINGS_VERSION = 2  # of the stored chunks

# One row per hand seen in a frame: (column, shape after the row axis)
COLUMNS = {"frame": (), "hand_id": (), "side": (), "keypoints_2d": (21, 3), "world": (21, 3), "score": (),
           "box": (4,), "global_orient": (3,), "hand_pose": (15, 3), "camera_scale": (), "camera_trans": (2,),
           "valid": (), "reprojection_error_px": ()}
FIT_COLUMNS = ("global_orient", "hand_pose", "camera_scale", "camera_trans", "valid", "reprojection_error_px")


@dataclass(frozen=True)
class HandChunk:
    """One chunk of frames: ``frame_index (n,)``, the hands seen as a table of `COLUMNS` (``frame`` the row's
    position in the chunk; ``side`` 0 left, 1 right) and what the tracker carries on (``tracking``)."""

    frame_index: np.ndarray
    hands: dict[str, np.ndarray]
    tracking: dict[str, np.ndarray]

    def arrays(self) -> dict[str, np.ndarray]:
        return {"frame_index": self.frame_index} | {f"hands/{k}": v for k, v in self.hands.items()} | {
            f"tracking/{k}": v for k, v in self.tracking.items()}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> "HandChunk":
        def part(prefix):
            return {k.split("/", 1)[1]: v for k, v in arrays.items() if k.startswith(prefix)}
        return cls(arrays["frame_index"], part("hands/"), part("tracking/"))


def run_hands(config: RunConfig, out_dir) -> RunReport:
    """Run ``config`` in ``hands`` mode: ``out_dir/hands.npz`` (docs/formats.md), with ``max_hands`` above 2 also
    each tracked hand's ``out_dir/hands/<id>.npz``, OpenPose JSON of the hands in ``out_dir/keypoints/``, and the
    overlay (``overlay.mp4``) and glTF export (``hands.glb``) ``config`` asks for."""
    out_dir = Path(out_dir)
    if "bvh" in config.exports:
        raise InputError("--mode hands exports glTF only (--export gltf); BVH holds one skeleton")
    (out_dir / "keypoints").mkdir(parents=True, exist_ok=True)
    model_path = smplx_jax.model_path(config.model)
    model, model_sha256 = smplx_jax.load_model(model_path), file_sha256(model_path)
    regression = None
    if config.weights is not None:
        from jaxmocap.pipeline.regress import Regression

        regression = Regression.load(config.weights, model)
    media, frames = open_media(config.source, config.start, config.end, config.stride)
    still = media.kind in ("image", "images")
    tracker = HandTracker(static_image_mode=still, max_hands=config.max_hands)
    store = ChunkStore(out_dir, chunk_key(config, model_sha256) | {"version": SETTINGS_VERSION}, HandChunk)
    clock = StageClock()
    solve = functools.partial(solve_hand_chunk, tracker, model, {s: hand_keypoint_model(model, s) for s in SIDES},
                              regression, config.iterations)
    chunks = list(solved_hand_chunks(config, media, frames, tracker, store, solve, out_dir, clock))
    frames_total = sum(len(c.frame_index) for c in chunks)
    table = whole_table(chunks)
    meta = {"fps": np.asarray(media.fps), "image_size": np.asarray(media.size),
            "model_sha256": np.asarray(model_sha256)}
    hand_models = {side: smplx_jax.hand_model(model, side) for side in SIDES}
    fit = functools.partial(fitted_side, model, lens_of(media.size, config.focal_length), media.fps) if (
        config.smooth and not still) else None
    with clock("clip"):
        hands = side_arrays(table, frames_total, fit)
    with clock("write"):
        written = [write_hands(out_dir / "hands.npz", hands | meta)]
        if config.max_hands > 2:
            for hand_id in np.unique(table["hand_id"]):
                own = {k: v[table["hand_id"] == hand_id] for k, v in table.items()}
                written.append(write_hands(out_dir / "hands" / f"{int(hand_id)}.npz",
                                           side_arrays(own, frames_total, fit) | meta))
    if config.overlay:
        with clock("overlay"):
            written.append(write_hands_overlay(out_dir / "overlay.mp4", config, hand_models, hands, media.fps,
                                               media.size, frames_total))
    if "gltf" in config.exports and (hands["left_valid"].any() or hands["right_valid"].any()):
        from jaxmocap.export.hands_gltf import write_hands_gltf

        with clock("exports"):
            written.append(write_hands_gltf(out_dir / "hands.glb", model, hands | meta))
    store.clear()
    valid = int((hands["left_valid"] | hands["right_valid"]).sum())
    return RunReport(written[0], frames_total, valid, dict(clock.seconds), written,
                     sorted(int(i) for i in np.unique(table["hand_id"])))


def solved_hand_chunks(config: RunConfig, media, frames, tracker: HandTracker, store: ChunkStore, solve,
                       out_dir: Path, clock: StageClock):
    """Each chunk of frames, from the store if it holds it (the tracker restored from it), else solved
    (``solve(ids, frames, clock)``), stored, and its hands written as OpenPose JSON."""
    from tqdm import tqdm

    with tqdm(total=media.frame_count, unit="frame", desc="hands", disable=not config.progress) as bar:
        yield from stored_or_solved(
            frames, config.chunk_size, store, clock, lambda ids, frames, _: solve(ids, frames, clock),
            lambda chunk, first: write_hand_keypoints(out_dir / "keypoints", media, chunk, first, config.max_hands),
            lambda chunk: tracker.restore(chunk.tracking), bar)


def solve_hand_chunk(tracker: HandTracker, model, keypoint_models, regression, iterations: int, ids: np.ndarray,
                     frames: list[np.ndarray], clock: StageClock) -> HandChunk:
    """One chunk of frames through the hand tracker and each hand's fit."""
    with clock("detect"):
        table = detected(tracker, frames)
    with clock("fit"):
        table |= fitted(model, keypoint_models, table, frames, regression, iterations)
    return HandChunk(ids, table, tracker.state())


def detected(tracker: HandTracker, frames: list[np.ndarray]) -> dict[str, np.ndarray]:
    """The hands of each frame (the tracker carries on from the frames before) as rows of `COLUMNS`' detection
    columns; a keypoint's confidence is its hand's presence."""
    rows = []
    for n, frame in enumerate(frames):
        for hand in tracker(frame):
            rows.append((n, hand.hand_id, SIDES.index(hand.side), hand.keypoints_2d, hand.world, hand.score,
                         hand.box))
    names = ("frame", "hand_id", "side", "keypoints_2d", "world", "score", "box")
    return {name: np.asarray([r[k] for r in rows], np.float32 if k > 2 else np.int64).reshape(
        (len(rows),) + COLUMNS[name]) for k, name in enumerate(names)}


def fitted(model, keypoint_models, table, frames, regression, iterations: int) -> dict[str, np.ndarray]:
    """`FIT_COLUMNS` of each row of a chunk's table: each side's hands fitted in one batch, from IK of their world
    landmarks, or from the hand regressor's prediction on their boxes (``regression``)."""
    out = {k: np.zeros((len(table["frame"]),) + COLUMNS[k], bool if k == "valid" else np.float32)
           for k in FIT_COLUMNS}
    for k, side in enumerate(SIDES):
        rows = np.flatnonzero(table["side"] == k)
        if not len(rows):
            continue
        start, ok = (None, True) if regression is None else regressed(model, regression, table, rows, frames, side)
        result = fit_hands(model, side, table["world"][rows], np.ones((len(rows), 21)), table["keypoints_2d"][rows],
                           start=start, km=keypoint_models[side], iterations=iterations)
        for name in FIT_COLUMNS:
            out[name][rows] = getattr(result, name)
        out["valid"][rows] &= ok
    return out


def regressed(model, regression, table, rows, frames, side: str):
    """FrankMocap's hand regressor on the boxes of the ``rows`` (all of one side): ``(global_orient, hand_pose)``
    as the start of the fit, and where its crop could be cut."""
    from jaxmocap.regressors import decode_hands, predict_hands

    images = np.stack(frames)
    boxes = table["box"][rows]
    xywh = np.concatenate([boxes[:, :2], boxes[:, 2:] - boxes[:, :2]], axis=1)
    is_left = np.full(len(rows), side == "left")
    raw, window, ok = predict_hands(regression.predictor, images, table["frame"][rows], xywh, is_left)
    hands = decode_hands(model, regression.right_hand, jnp.nan_to_num(raw), is_left, window)
    return (np.asarray(hands.wrist_glob_rotvec), np.asarray(hands.hand_pose)), ok


def whole_table(chunks: list[HandChunk]) -> dict[str, np.ndarray]:
    """The chunks' tables as one, ``frame`` counted from the run's first frame."""
    offsets = np.cumsum([0] + [len(c.frame_index) for c in chunks[:-1]])
    parts = [c.hands | {"frame": c.hands["frame"] + offset} for c, offset in zip(chunks, offsets)]
    return {k: np.concatenate([p[k] for p in parts]) if parts else np.zeros((0,) + COLUMNS[k]) for k in COLUMNS}


def side_arrays(table: dict[str, np.ndarray], frames: int, fit=None) -> dict[str, np.ndarray]:
    """hands.npz's per-side arrays over ``frames`` frames: in each frame the side's likeliest hand (highest
    presence) of the table; each side's frames fitted as one by ``fit(side, arrays, world)`` (`fitted_side` with
    its model, lens and frame rate given; None: each frame's own fit)."""
    out = {}
    for k, side in enumerate(SIDES):
        arrays = {name: np.zeros((frames,) + shape, bool if name == "valid" else np.float32)
                  for name, shape in HAND_SHAPES.items()}
        arrays["camera_scale"][:] = 1.0
        world = np.zeros((frames, 21, 3), np.float32)
        rows = np.flatnonzero(table["side"] == k)
        rows = rows[np.lexsort((table["score"][rows], table["frame"][rows]))]  # by frame, the likeliest last
        at = table["frame"][rows].astype(int)
        for name in arrays:
            arrays[name][at] = table[name][rows]
        world[at] = table["world"][rows]
        if fit is not None and arrays["valid"].any():
            arrays = fit(side, arrays, world)
        out |= {f"{side}_{name}": value for name, value in arrays.items()}
    return out


@disk_jit(static_argnames="side")
def _fit_window(model, side, keypoints, start, focal_length, principal_point, fps, sigma, directions, weight, found):
    return fit_hand_clip(model, side, keypoints, start, focal_length=focal_length, principal_point=principal_point,
                         fps=fps, keypoint_sigma_px=sigma, directions=directions, direction_weight=weight,
                         found=found)


def fitted_side(model: smplx_jax.BodyModel, lens, fps: float, side: str, arrays: dict[str, np.ndarray],
                world: Float[ArrayLike, "T 21 3"]) -> dict[str, np.ndarray]:
    """One side's arrays (`HAND_SHAPES`, each frame's own fit) over a video at ``fps`` as one fit
    (`integrate.hand_clip`) from those fits: its keypoints, each keypoint's noise (`whole_clip.part_noise_px`) and
    its bones' directions from the 3D landmarks ``world`` (`whole_clip.hand_bone_directions`, through the pinhole
    ``lens``), in windows placed by frame number (`whole_clip.window_spans`): the result does not depend on the
    chunks the run was stored in. Valid where the frame's own fit was and the result is finite."""
    valid = arrays["valid"]
    keypoints = arrays["keypoints_2d"]
    sigma = np.repeat(part_noise_px(keypoints)[:, None], 21, 1).astype(np.float32)
    directions, weight = (np.asarray(a, np.float32) for a in hand_bone_directions(keypoints, world,
                                                                                   keypoints[:, 0, 2], lens))
    start = jax.tree.map(np.asarray, hand_clip_start(*(arrays[k] for k in (
        "global_orient", "hand_pose", "camera_scale", "camera_trans"))))
    focal, centre = np.float32(lens[0]), np.asarray(lens[1], np.float32)
    parts = []
    for frames, inside, keep in window_spans(len(valid)):
        window = start._replace(pose_rotvecs=start.pose_rotvecs[frames], transl=start.transl[frames])
        result = _fit_window(model, side, keypoints[frames], window, focal, centre, np.float32(fps), sigma[frames],
                             directions[frames], weight[frames], inside & valid[frames])
        parts.append({k: np.asarray(v)[keep] for k, v in result._asdict().items() if k in HAND_SHAPES})
    fitted = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
    finite = np.all(np.isfinite(np.concatenate([fitted["global_orient"], fitted["hand_pose"].reshape(len(valid), -1),
                                                fitted["camera_trans"]], 1)), 1)
    ok = valid & finite
    out = {k: np.where(ok.reshape((-1,) + (1,) * (v.ndim - 1)), v, arrays[k]).astype(np.float32)
           for k, v in fitted.items()}
    return arrays | out | {"valid": ok}


def write_hand_keypoints(folder: Path, media, chunk: HandChunk, first: int, max_hands: int) -> None:
    """The chunk's hands as OpenPose JSON, one file per frame, hands only (`detect.hand_json.hands_openpose`)."""
    table = chunk.hands
    for n, frame in enumerate(chunk.frame_index):
        name = json_name(media.stems[first + n], None) if media.stems else json_name(media.stem, int(frame))
        rows = table["frame"] == n
        people, ids = hands_openpose(table["side"][rows], table["keypoints_2d"][rows], table["score"][rows],
                                     table["hand_id"][rows], max_hands)
        write_openpose_json(folder / name, people, ids, body=False)


def write_hands_overlay(path: Path, config: RunConfig, hand_models: dict, hands: dict, fps: float,
                        image_size: tuple[int, int], total: int, batch: int = 16) -> Path:
    """The run's frames with the fitted hand meshes drawn over them (left in one colour, right in another, each
    labelled), beside a side view; written atomically."""
    _, frames = open_media(config.source, config.start, config.end, config.stride)
    from tqdm import tqdm

    meshes = {side: np.asarray(hand_meshes(hand_models[side], hands[f"{side}_global_orient"],
                                           hands[f"{side}_hand_pose"]).vertices) for side in SIDES}
    faces = {side: np.asarray(hand_models[side].faces) for side in SIDES}
    with atomic_path(path) as tmp, OverlayWriter(tmp, image_size, fps, faces["right"]) as writer, \
            tqdm(total=total, unit="frame", desc="overlay", disable=not config.progress) as bar:
        for start in range(0, total, batch):
            images = [frame for _, (_, frame) in zip(range(min(batch, total - start)), frames)]
            posed = [[Posed(k, meshes[side][t], float(hands[f"{side}_camera_scale"][t]),
                            hands[f"{side}_camera_trans"][t], faces[side], side[0].upper())
                      for k, side in enumerate(SIDES) if hands[f"{side}_valid"][t]]
                     for t in range(start, start + len(images))]
            writer.write(*zip(images, posed))
            bar.update(len(images))
    return Path(path)


__all__ = ["HandChunk", "run_hands"]
