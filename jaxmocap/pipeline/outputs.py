"""What a run writes besides motion.npz: the overlay video and the animation exports."""

from pathlib import Path

import jax
import numpy as np
from tqdm import tqdm

import smplx_jax
from jaxmocap.export import animation, write_bvh, write_gltf
from jaxmocap.media import open_media
from jaxmocap.motion import lens, motion_params
from jaxmocap.overlay import OverlayWriter, body_up

EXPORT_FILES = {"bvh": "motion.bvh", "gltf": "motion.glb"}
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
            padded = np.concatenate([ids, np.full(_BATCH - len(ids), ids[-1])])  # one compiled batch size
            vertices = np.asarray(_VERTICES(model, motion_params(motion, model.num_expression, padded)))
            writer.write(*[(frame, vertices[k], faces, float(motion["camera_scale"][i]), motion["camera_trans"][i])
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
