"""What a run writes besides motion.npz: the detections as OpenPose JSON (per chunk), and at the end FrankMocap's
prediction pickles, the overlay video and the animation exports."""

from pathlib import Path

import jax
import numpy as np
from tqdm import tqdm

import smplx_jax
from jaxmocap.batching import pad_rows
from jaxmocap.detect.openpose import json_name, write_openpose_json
from jaxmocap.export import animation, write_bvh, write_gltf
from jaxmocap.export.frankmocap import write_frankmocap_pkls
from jaxmocap.frame_source import Media, open_media
from jaxmocap.motion import lens, motion_params
from jaxmocap.overlay import OverlayWriter, body_up
from jaxmocap.pipeline.chrono import Chrono
from jaxmocap.pipeline.config import EXPORT_FILES, RunConfig
from jaxmocap.pipeline.records import Chunk
_VERTICES = jax.jit(jax.vmap(lambda model, params: smplx_jax.forward(model, params).vertices, in_axes=(None, 0)))
_BATCH = 16


def write_overlay(path: Path, model: smplx_jax.BodyModel, motion: dict, source, start, end, stride,
                  progress: bool = True) -> Path:
    """The frames again, each with its fitted mesh drawn over it, beside a side view."""
    media, frames = open_media(source, start, end, stride)
    faces = np.asarray(model.faces)
    valid = motion["valid"]
    total = len(valid)
    up = body_up(motion["global_orient"][valid]) if valid.any() else None
    with OverlayWriter(path, media.size, media.fps, lens=lens(motion), up=up) as writer:
        bar = tqdm(total=total, unit="frame", desc="overlay", disable=not progress)
        done = 0
        while done < total:
            batch = [frame for _, (_, frame) in zip(range(_BATCH), frames)]
            if not batch:
                break
            ids = np.arange(done, done + len(batch))
            padded = pad_rows(ids, _BATCH)  # one compiled batch size
            vertices = np.asarray(_VERTICES(model, motion_params(motion, model.num_expression, padded)))
            writer.write(*[(frame, vertices[k], faces, motion["camera_scale"][i], motion["camera_trans"][i])
                           if valid[i] else (frame,) for k, (i, frame) in enumerate(zip(ids, batch))])
            done += len(batch)
            bar.update(len(batch))
        bar.close()
    return Path(path)


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
    """The chunk's detections as OpenPose JSON, one file per frame (``first``: the chunk's first frame's position
    in the run), named after the image or the video's stem and frame number."""
    for n, (frame, found) in enumerate(zip(chunk.frame_index, chunk.found)):
        name = json_name(media.stems[first + n], None) if media.stems else json_name(media.stem, int(frame))
        write_openpose_json(folder / name, chunk.keypoints_2d[n][None] if found else np.zeros((0, 67, 3)))


def write_outputs(config: RunConfig, out_dir: Path, model: smplx_jax.BodyModel, media: Media, motion: dict,
                  chunks: list[Chunk], chrono: Chrono) -> list[Path]:
    """What ``config`` asks for besides ``motion.npz``: FrankMocap's pickles, the overlay video, the exports."""
    written = []
    if config.frankmocap_pkl:
        with chrono("frankmocap"):
            boxes = [np.concatenate([getattr(c, k) for c in chunks]) for k in ("body_box", "hand_boxes")]
            frames = np.concatenate([c.frame_index for c in chunks])
            written += write_frankmocap_pkls(out_dir, model, motion, *boxes, _frame_images(media, out_dir, frames))
    if config.overlay:
        with chrono("overlay"):
            written.append(write_overlay(out_dir / "overlay.mp4", model, motion, config.source, config.start,
                                         config.end, config.stride, progress=config.progress))
    if config.exports:
        with chrono("exports"):
            written += write_exports(out_dir, model, motion, config.exports)
    return written


def _frame_images(media: Media, out_dir: Path, frame_ids) -> list[Path]:
    """Each frame's image as FrankMocap names it: the image file, else ``frames/<frame:05d>.jpg`` (a webcam's
    ``frames/scene_<frame:05d>.jpg``), which FrankMocap writes only with ``--save_frame``."""
    if media.paths:
        return list(media.paths)
    prefix = "scene_" if media.kind == "webcam" else ""
    return [out_dir / "frames" / f"{prefix}{i:05d}.jpg" for i in frame_ids]
