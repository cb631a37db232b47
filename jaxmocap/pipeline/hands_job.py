"""``jaxmocap run --mode hands``: hands on their own, no body needed (FrankMocap's hand demo: close-ups, ego-centric
video). Palms over the whole frame (`detect.hand_tracker`), up to ``max_hands``, tracked in a video, each with its
side; per hand IK from its 21 world landmarks and the optimistix fit to its 21 keypoints (`integrate.hand_fit`), or
with FrankMocap's weights the hand regressor on the hands' boxes, then the same fit. In chunks, resumable like the
whole-body run; then per side temporal smoothing -> ``hands.npz`` (the left and the right hand: in each frame the
likeliest of each side) -> OpenPose JSON of the hands, overlay, glTF.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import smplx_jax
from jaxmocap.detect.detector import search_interval
from jaxmocap.detect.hand_json import hands_openpose
from jaxmocap.detect.hand_tracker import SIDES, HandTracker
from jaxmocap.detect.openpose import json_name, write_openpose_json
from jaxmocap.errors import InputError
from jaxmocap.frame_source import open_media
from jaxmocap.hand_motion import HAND_SHAPES, hand_meshes, write_hands
from jaxmocap.integrate.hand_fit import fit_hands, hand_keypoint_model
from jaxmocap.integrate.smooth import smooth_linear, smooth_rotvecs
from jaxmocap.io import atomic_path, file_sha256
from jaxmocap.overlay import OverlayWriter, Posed
from jaxmocap.pipeline.chrono import Chrono
from jaxmocap.pipeline.chunks import ChunkStore, frame_batches
from jaxmocap.pipeline.config import RunConfig, chunk_key
from jaxmocap.pipeline.report import RunReport

SETTINGS_VERSION = 1  # of the stored chunks
# (times, pixels): how much farther from its keypoints than its own fit a smoothed hand may reproject before the frame
# keeps its fit. Each frame's hand is fitted alone, and one frame's fit can turn the hand round in depth from the
# next's (each matches its image, their average neither): smoothing a moving hand over a few frames moves its
# keypoints by a fraction of its fit's error, an average across such a turn by the hand's size.
SMOOTHING_SLACK = (3.0, 20.0)

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
    model_path = Path(config.model) if config.model else smplx_jax.default_model_path()
    model, model_sha256 = smplx_jax.load_model(model_path), file_sha256(model_path)
    regression = None
    if config.weights is not None:
        from jaxmocap.pipeline.regress import Regression

        regression = Regression.load(config.weights, model)
    media, frames = open_media(config.source, config.start, config.end, config.stride)
    still = media.kind in ("image", "images")
    tracker = HandTracker(static_image_mode=still, max_hands=config.max_hands,
                          redetect_every=search_interval(media.fps))
    store = ChunkStore(out_dir, chunk_key(config, model_sha256) | {"version": SETTINGS_VERSION}, HandChunk)
    chrono = Chrono()
    solve = functools.partial(solve_hand_chunk, tracker, model, {s: hand_keypoint_model(model, s) for s in SIDES},
                              regression, config.iterations)
    chunks = list(solved_hand_chunks(config, media, frames, tracker, store, solve, out_dir, chrono))
    frames_total = sum(len(c.frame_index) for c in chunks)
    table = whole_table(chunks)
    meta = {"fps": np.asarray(media.fps), "image_size": np.asarray(media.size),
            "model_sha256": np.asarray(model_sha256)}
    hand_models = {side: smplx_jax.hand_model(model, side) for side in SIDES}
    with chrono("smooth"):
        hands = side_arrays(table, frames_total, hand_models, config.smooth)
    with chrono("write"):
        written = [write_hands(out_dir / "hands.npz", hands | meta)]
        if config.max_hands > 2:
            for hand_id in np.unique(table["hand_id"]):
                own = {k: v[table["hand_id"] == hand_id] for k, v in table.items()}
                written.append(write_hands(out_dir / "hands" / f"{int(hand_id)}.npz",
                                           side_arrays(own, frames_total, hand_models, config.smooth) | meta))
    if config.overlay:
        with chrono("overlay"):
            written.append(write_hands_overlay(out_dir / "overlay.mp4", config, hand_models, hands, media.fps,
                                               media.size, frames_total))
    if "gltf" in config.exports and (hands["left_valid"].any() or hands["right_valid"].any()):
        from jaxmocap.export.hands_gltf import write_hands_gltf

        with chrono("exports"):
            written.append(write_hands_gltf(out_dir / "hands.glb", model, hands | meta))
    store.clear()
    valid = int((hands["left_valid"] | hands["right_valid"]).sum())
    return RunReport(written[0], frames_total, valid, dict(chrono.seconds), written,
                     sorted(int(i) for i in np.unique(table["hand_id"])))


def solved_hand_chunks(config: RunConfig, media, frames, tracker: HandTracker, store: ChunkStore, solve,
                       out_dir: Path, chrono: Chrono):
    """Each chunk of frames, from the store if it holds it (the tracker restored from it), else solved
    (``solve(ids, frames, chrono)``), stored, and its hands written as OpenPose JSON."""
    from tqdm import tqdm

    done = 0
    with tqdm(total=media.frame_count, unit="frame", desc="hands", disable=not config.progress) as bar:
        for index, batch in frame_batches(frames, config.chunk_size, chrono):
            ids = np.asarray([i for i, _ in batch])
            chunk = store.load(index)
            if chunk is None or not np.array_equal(chunk.frame_index, ids):
                chunk = solve(ids, [frame for _, frame in batch], chrono)
                with chrono("keypoints"):  # before the chunk is stored: a stored chunk has its JSON written
                    write_hand_keypoints(out_dir / "keypoints", media, chunk, done, config.max_hands)
                store.save(index, chunk)
            else:
                tracker.restore(chunk.tracking)
            del batch  # its frames go before the next chunk's are read
            yield chunk
            done += len(ids)
            bar.update(len(ids))
            bar.set_postfix(fps=f"{done / max(chrono.total, 1e-9):.1f}")


def solve_hand_chunk(tracker: HandTracker, model, keypoint_models, regression, iterations: int, ids: np.ndarray,
                     frames: list[np.ndarray], chrono: Chrono) -> HandChunk:
    """One chunk of frames through the hand tracker and each hand's fit."""
    with chrono("detect"):
        table = detected(tracker, frames)
    with chrono("fit"):
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


def side_arrays(table: dict[str, np.ndarray], frames: int, hand_models: dict, smooth: bool) -> dict[str, np.ndarray]:
    """hands.npz's per-side arrays over ``frames`` frames: in each frame the side's likeliest hand (highest
    presence) of the table; smoothed over time (``smooth``), except where smoothing would take a hand off its
    keypoints (`SMOOTHING_SLACK`)."""
    out = {}
    for k, side in enumerate(SIDES):
        arrays = {name: np.zeros((frames,) + shape, bool if name == "valid" else np.float32)
                  for name, shape in HAND_SHAPES.items()}
        arrays["camera_scale"][:] = 1.0
        rows = np.flatnonzero(table["side"] == k)
        rows = rows[np.lexsort((table["score"][rows], table["frame"][rows]))]  # by frame, the likeliest last
        for name in arrays:
            arrays[name][table["frame"][rows].astype(int)] = table[name][rows]
        if smooth and arrays["valid"].any():
            arrays = smoothed_side(arrays, hand_models[side])
        out |= {f"{side}_{name}": value for name, value in arrays.items()}
    return out


@jax.jit
def _smooth_side(global_orient, hand_pose, camera_scale, camera_trans, valid):
    rotations = smooth_rotvecs(jnp.concatenate([global_orient[:, None], hand_pose], 1), valid)  # one conversion
    camera = smooth_linear(jnp.concatenate([camera_scale[:, None], camera_trans], 1), valid)
    return {"global_orient": rotations[:, 0], "hand_pose": rotations[:, 1:], "camera_scale": camera[:, 0],
            "camera_trans": camera[:, 1:]}


def smoothed_side(arrays: dict[str, np.ndarray], hand: smplx_jax.HandModel) -> dict[str, np.ndarray]:
    """One side's rotations (as quaternions) and camera filtered over time across valid frames; a frame whose
    smoothed hand reprojects more than `SMOOTHING_SLACK` farther than its own fit keeps its fit."""
    smooth = arrays | {k: np.asarray(v) for k, v in _smooth_side(
        *(arrays[k] for k in ("global_orient", "hand_pose", "camera_scale", "camera_trans", "valid"))).items()}
    errors = reprojection_errors(hand, smooth)
    ratio, pixels = SMOOTHING_SLACK
    keep = arrays["valid"] & (errors > np.maximum(ratio * arrays["reprojection_error_px"],
                                                  arrays["reprojection_error_px"] + pixels))
    out = {k: np.where(keep.reshape((-1,) + (1,) * (v.ndim - 1)), arrays[k], v) for k, v in smooth.items()}
    out["reprojection_error_px"] = np.where(keep | ~arrays["valid"], arrays["reprojection_error_px"], errors)
    return out


def reprojection_errors(hand: smplx_jax.HandModel, arrays: dict[str, np.ndarray]) -> np.ndarray:
    """(T,) mean pixel distance of one side's hand joints from its keypoints with confidence > 0 (0 if none)."""
    joints = np.asarray(hand_meshes(hand, arrays["global_orient"], arrays["hand_pose"]).joints)
    pixels = arrays["camera_scale"][:, None, None] * joints[..., :2] + arrays["camera_trans"][:, None]
    seen = arrays["keypoints_2d"][..., 2] > 0
    distance = np.linalg.norm(pixels - arrays["keypoints_2d"][..., :2], axis=-1)
    return (np.where(seen, distance, 0).sum(1) / np.maximum(seen.sum(1), 1)).astype(np.float32)


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
