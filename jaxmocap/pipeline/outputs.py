"""What a run writes besides the motions: the detections as OpenPose JSON (per chunk), and at the end FrankMocap's
prediction pickles, the overlay video and the animation exports."""

from pathlib import Path

import cv2
import jax
import numpy as np
from tqdm import tqdm

import smplx_jax
from jaxmocap.buckets import pad_rows
from jaxmocap.detect.openpose import json_name, write_openpose_json
from jaxmocap.export import animation, write_bvh, write_gltf
from jaxmocap.export.frankmocap import write_frankmocap_pkls
from jaxmocap.frame_source import Media, open_media
from jaxmocap.integrate.ground import camera_floors
from jaxmocap.motion import lens, motion_params
from jaxmocap.overlay import OverlayWriter, Posed, body_up
from jaxmocap.pipeline.config import EXPORT_FILES, RunConfig
from jaxmocap.pipeline.stage_clock import StageClock
from jaxmocap.pipeline.tracks import Chunk, Track
from smplx_jax.atomic_files import atomic_path, atomic_write_bytes

_VERTICES = jax.jit(jax.vmap(lambda model, params: smplx_jax.forward(model, params).vertices, in_axes=(None, 0)))
_BATCH = 16


def write_overlay(path: Path, model: smplx_jax.BodyModel, motions: dict[int, dict], config: RunConfig,
                  image_size: tuple[int, int], total: int) -> Path:
    """The ``total`` frames of the run again, each with its people's fitted meshes drawn over it in their colours
    with their identities, beside a side view of them; written atomically (an interrupted run leaves none)."""
    media, frames = open_media(config.source, config.start, config.end, config.stride)
    faces = np.asarray(model.faces)
    orients = [m["global_orient"][m["valid"]] for m in motions.values()]
    up = body_up(np.concatenate(orients)) if sum(map(len, orients)) else None
    lenses = lens(next(iter(motions.values()))) if motions else (None, None)
    world = next((m["camera_from_world"] for m in motions.values() if "camera_from_world" in m), None)  # everyone's
    floors = [None] * total if world is None else camera_floors(np.asarray(world, np.float64))
    with atomic_path(path) as tmp, \
            OverlayWriter(tmp, image_size, media.fps, faces, lens=lenses, up=up, spread=_spread(motions)) as writer, \
            tqdm(total=total, unit="frame", desc="overlay", disable=not config.progress) as bar:
        for start in range(0, total, _BATCH):
            batch = [frame for _, (_, frame) in zip(range(min(_BATCH, total - start)), frames)]
            if not batch:
                break
            rows = pad_rows(np.arange(start, start + len(batch)), _BATCH)  # one compiled batch size
            people = [[] for _ in batch]
            for person_id, motion in motions.items():
                vertices = np.asarray(_VERTICES(model, motion_params(motion, model.num_expression, rows)))
                for k, t in enumerate(rows[:len(batch)]):
                    if motion["valid"][t]:
                        people[k].append(Posed(person_id, vertices[k], float(motion["camera_scale"][t]),
                                               motion["camera_trans"][t]))
            writer.write(*zip(batch, people, floors[start:start + len(batch)]))
            bar.update(len(batch))
    return Path(path)


def _spread(motions: dict[int, dict]) -> float:
    """The most the people of one frame are apart (metres, in depth or height: the side view's axes)."""
    if len(motions) < 2:
        return 0.0
    transl = np.stack([m["transl"] for m in motions.values()])  # (P, T, 3)
    valid = np.stack([m["valid"] for m in motions.values()])[..., None]
    lo, hi = np.where(valid, transl, np.inf).min(axis=0), np.where(valid, transl, -np.inf).max(axis=0)
    return float(np.nan_to_num(hi - lo, neginf=0.0)[:, 1:].max(initial=0.0))


def write_exports(out_dir: Path, model: smplx_jax.BodyModel, motion: dict, formats) -> list[Path]:
    """``motion.bvh`` / ``motion.glb`` for the formats asked (``EXPORT_FILES``); none without a valid frame."""
    if not motion["valid"].any():
        return []
    anim = animation(model, motion)
    written = []
    for fmt in formats:
        path = Path(out_dir) / EXPORT_FILES[fmt]
        written.append(write_bvh(path, anim) if fmt == "bvh" else write_gltf(path, model, anim))
    return written


def write_keypoints(folder: Path, media: Media, chunk: Chunk, first: int) -> None:
    """The chunk's detections as OpenPose JSON, one file per frame listing every person with their
    ``person_id`` (``first``: the chunk's first frame's position in the run), named after the image or the
    video's stem and frame number."""
    for n, frame in enumerate(chunk.frame_index):
        name = json_name(media.stems[first + n], None) if media.stems else json_name(media.stem, int(frame))
        seen = [(i, t.keypoints_2d[n]) for i, t in chunk.people.items() if t.found[n]]
        write_openpose_json(folder / name, np.asarray([k for _, k in seen]).reshape(-1, 67, 3),
                            person_ids=[i for i, _ in seen])


def write_outputs(config: RunConfig, out_dir: Path, model: smplx_jax.BodyModel, media: Media,
                  motions: dict[int, dict], main: int | None, tracks: dict[int, Track], chunks: list[Chunk],
                  clock: StageClock) -> list[Path]:
    """What ``config`` asks for besides the motions: FrankMocap's pickles (every person of each frame), the
    overlay video (everyone), the exports (the main person's in ``out_dir``, each person's in
    ``out_dir/people/<id>``)."""
    written = []
    if config.frankmocap_pkl:
        with clock("frankmocap"):
            frames = np.concatenate([c.frame_index for c in chunks])
            people = {i: (motions[i], tracks[i].body_box, tracks[i].hand_boxes) for i in motions}
            written += write_frankmocap_pkls(out_dir, model, people, _frame_images(media, out_dir, frames))
    if config.save_frames and not media.paths:
        with clock("frames"):
            written += write_frames(out_dir, config, media)
    if config.overlay:
        with clock("overlay"):
            total = sum(len(c.frame_index) for c in chunks)
            written.append(write_overlay(out_dir / "overlay.mp4", model, motions, config, media.size, total))
    if config.exports:
        with clock("exports"):
            if main is not None:
                written += write_exports(out_dir, model, motions[main], config.exports)
            for person_id, motion in motions.items():
                written += write_exports(out_dir / "people" / str(person_id), model, motion, config.exports)
    return written


def write_frames(out_dir: Path, config: RunConfig, media: Media) -> list[Path]:
    """A video's (or webcam's) frames of the run as JPEG images where FrankMocap's ``--save_frame`` puts them and
    its pickles name them (`_frame_images`)."""
    _, frames = open_media(config.source, config.start, config.end, config.stride)
    written = []
    for index, image in frames:
        path = _frame_images(media, out_dir, [index])[0]
        ok, data = cv2.imencode(".jpg", image)
        if not ok:
            raise OSError(f"cannot encode frame image {path}")
        written.append(atomic_write_bytes(path, data.tobytes()))
    return written


def _frame_images(media: Media, out_dir: Path, frame_ids) -> list[Path]:
    """Each frame's image as FrankMocap names it: the image file, else ``frames/<frame:05d>.jpg`` (a webcam's
    ``frames/scene_<frame:05d>.jpg``), which FrankMocap writes only with ``--save_frame``."""
    if media.paths:
        return list(media.paths)
    prefix = "scene_" if media.kind == "webcam" else ""
    return [out_dir / "frames" / f"{prefix}{i:05d}.jpg" for i in frame_ids]
