"""The FrankMocap path: body and hand regressors on the detector's boxes, copy-and-paste (optionally the body
fine-tuned per frame, EFT)."""

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

import smplx_jax
from jaxmocap.integrate import copy_paste
from jaxmocap.pipeline.exemplar import fine_tuned_bodies
from jaxmocap.pipeline.hand_boxes import hand_boxes_from_body
from jaxmocap.pipeline.observe import Observations
from jaxmocap.pipeline.tracks import Bodies
from jaxmocap.regressors import Predictor, crops, decode_bodies, decode_hands, load, predict_bodies, predict_hands
from smplx_jax import constants
from smplx_jax.rotations import rotmat_to_rotvec

FRAMES_PER_BATCH = 16  # frames held as one image batch for cropping (memory: 16 x H x W x 3 bytes)
_PASTE = jax.jit(jax.vmap(copy_paste, in_axes=(None, 0, 0, 0, 0, 0)))


@dataclass(frozen=True)
class Regression:
    """Loaded networks and what decoding them needs (built once per run). ``hand_boxes``: where the hand
    regressor's crops come from, the detector's hand ``keypoints`` or the ``body`` regressor's projected hands
    (`hand_boxes_from_body`); None: the hand regressor does not run, hands stay flat (``--mode body``)."""

    predictor: Predictor
    right_hand: smplx_jax.HandModel
    hand_boxes: str | None = "keypoints"

    @classmethod
    def load(cls, weights_dir, model: smplx_jax.BodyModel, hand_boxes: str | None = "keypoints") -> "Regression":
        return cls(Predictor(load(weights_dir)), smplx_jax.hand_model(model, "right"), hand_boxes)


def _xywh(boxes):
    return np.concatenate([boxes[..., :2], boxes[..., 2:] - boxes[..., :2]], axis=-1)


def _pixel_camera(camera, window):
    """The weak-perspective camera (pixel = s X[:2] + t; docs/formats.md, "Coordinates and cameras") equal to the
    body crop's camera."""
    basis = jnp.broadcast_to(jnp.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), (camera.shape[0], 2, 3))
    pixels = crops.body_to_image(basis, camera, window)
    return pixels[:, 1, 0] - pixels[:, 0, 0], pixels[:, 0]


def _regress(model, reg: Regression, frames, obs: Observations, rows, eft: bool):
    """Copy-and-paste bodies of the frames ``rows`` (without a hand regressor, the bodies with flat hands), their
    pixel cameras, ``ok`` where the body was cropped, and the hand boxes used (N, 2, 4; NaN without one)."""
    images = np.stack([frames[i] for i in rows])
    local = np.arange(len(rows))
    body_boxes = _xywh(obs.body_box[rows])
    body_raw, body_window, body_ok = (
        fine_tuned_bodies(reg.predictor, model, images, local, body_boxes, obs.keypoints[rows]) if eft
        else predict_bodies(reg.predictor, images, local, body_boxes))
    body = decode_bodies(model, body_raw, body_window)
    safe = jax.tree.map(lambda a: jnp.where(jnp.isfinite(a), a, 0.0), body.params)
    scale, trans = _pixel_camera(jnp.where(jnp.isfinite(body_raw.camera), body_raw.camera, 1.0), body_window)
    if reg.hand_boxes is None:
        flat = jnp.zeros_like(safe.left_hand_pose)
        return (safe.replace(left_hand_pose=flat, right_hand_pose=flat), np.asarray(scale), np.asarray(trans),
                body_ok, np.full((len(rows), 2, 4), np.nan))
    hand_boxes = (hand_boxes_from_body(np.asarray(body.joints_2d), images.shape[2:0:-1]) if reg.hand_boxes == "body"
                  else obs.hand_boxes[rows])
    boxes = _xywh(hand_boxes.reshape(-1, 4))
    is_left = np.tile([True, False], len(rows))
    hand_raw, hand_window, hand_ok = predict_hands(reg.predictor, images, np.repeat(local, 2), boxes, is_left)
    hands = decode_hands(model, reg.right_hand, hand_raw, is_left, hand_window)
    hand_ok = hand_ok.reshape(-1, 2)
    glob = jax.vmap(smplx_jax.posed_skeleton, in_axes=(None, 0))(model, body.params).glob_rotmats
    own = rotmat_to_rotvec(glob[:, [constants.LEFT_WRIST, constants.RIGHT_WRIST]])  # the body's own wrists
    wrists = jnp.where(hand_ok[..., None], hands.wrist_glob_rotvec.reshape(-1, 2, 3), own)
    fingers = jnp.where(hand_ok[..., None, None], hands.hand_pose.reshape(-1, 2, 15, 3),
                        jnp.stack([body.params.left_hand_pose, body.params.right_hand_pose], axis=1))
    pasted = _PASTE(model, safe, fingers[:, 0], wrists[:, 0], fingers[:, 1], wrists[:, 1])
    return pasted, np.asarray(scale), np.asarray(trans), body_ok, hand_boxes


def regressed_bodies(model, reg: Regression, frames, obs: Observations, integration: str
                     ) -> tuple[Bodies, np.ndarray]:
    """Per-frame bodies of one chunk from the regressors (the body fine-tuned per frame with ``integration ==
    "eft"``) + copy-and-paste, their weak-perspective cameras, and the hand boxes (N, 2, 4) the hand regressor
    used."""
    parts = [_regress(model, reg, frames, obs, np.arange(s, min(s + FRAMES_PER_BATCH, len(frames))),
                      integration == "eft")
             for s in range(0, len(frames), FRAMES_PER_BATCH)]
    params = jax.tree.map(lambda *a: jnp.concatenate(a), *[p[0] for p in parts])
    scale, trans, ok, hand_boxes = (np.concatenate([p[k] for p in parts]) for k in (1, 2, 3, 4))
    ok = ok & obs.found & (scale > 0)
    return Bodies(jax.tree.map(np.asarray, params), scale, trans, ok), hand_boxes
