"""Synthetic fitting problems with known answers (tests and benchmarks): random plausible whole-body poses,
projected with a known weak-perspective camera (or a pinhole one, the body placed by ``transl``), with pixel noise
and dropped keypoints, and a perturbed start (`make_problem`); a body moving smoothly through a pinhole camera,
its keypoints and its bones' directions as the 3D landmarks give them (`make_clip`)."""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from jaxmocap.integrate import clip
from jaxmocap.integrate.fitting import default_pose, openpose_keypoint_model
from jaxmocap.integrate.motion_arrays import body_joints
from smplx_jax import BodyModel, SMPLXParams, constants, rotations

IMAGE_SIZE = (1000, 1000)


class Synthetic(NamedTuple):
    """Frames with known answers (`make_problem`): the true bodies and cameras, their keypoints, a start."""

    truth: SMPLXParams  # (T,)
    camera_scale: np.ndarray  # (T,) (pinhole: focal length / the body origin's depth)
    camera_trans: np.ndarray  # (T, 2) (pinhole: where the body origin's pixel is)
    clean: np.ndarray  # (T, 67, 2) exact projections
    keypoints: np.ndarray  # (T, 67, 3) noisy, some dropped (confidence 0)
    init: SMPLXParams  # (T,) perturbed truth


def random_pose(rng, t: int) -> np.ndarray:
    """(T, 55, 3) plausible poses in image axes (y down): upright, facing the camera +-30 degrees."""
    theta = np.zeros((t, 55, 3))
    yaw = rng.uniform(-0.5, 0.5, t)
    flip = np.array([np.pi, 0.0, 0.0])
    rot = rotations.rotvec_to_rotmat(jnp.asarray(flip)) @ rotations.rotvec_to_rotmat(
        jnp.asarray(np.stack([np.zeros(t), yaw, np.zeros(t)], 1)))
    theta[:, 0] = np.asarray(rotations.rotmat_to_rotvec(rot))
    theta[:, 1:22] = rng.normal(0, 0.2, (t, 21, 3))
    theta[:, 16, 2] += rng.uniform(-1.3, -0.3, t)  # left shoulder down
    theta[:, 17, 2] += rng.uniform(0.3, 1.3, t)
    theta[:, 18, 1] = -rng.uniform(0.1, 1.5, t)  # elbows bent the natural way
    theta[:, 19, 1] = rng.uniform(0.1, 1.5, t)
    theta[:, 4, 0] = rng.uniform(0.0, 1.0, t)  # knees
    theta[:, 5, 0] = rng.uniform(0.0, 1.0, t)
    curl = rng.uniform(0.0, 1.2, (t, 2, 5, 1))  # per finger
    hands = rng.normal(0, 0.1, (t, 2, 15, 3))
    hands[:, :, :12, 0] *= 0.2  # index to ring fingers are hinges: little twist, sideways only at the knuckle
    hands[:, :, [1, 2, 4, 5, 7, 8, 10, 11], 1] *= 0.2
    for side, sign in ((0, -1.0), (1, 1.0)):
        for finger in range(4):  # index, middle, pinky, ring curl about z, never backwards
            joints = slice(3 * finger, 3 * finger + 3)
            hands[:, side, joints, 2] = sign * (np.abs(hands[:, side, joints, 2]) + curl[:, side, finger])
        hands[:, side, 12:15, 1] += sign * 0.5 * curl[:, side, 4]
    theta[:, 25:40] = hands[:, 0]
    theta[:, 40:55] = hands[:, 1]
    return theta.astype(np.float32)


def _params(theta, betas, num_expression):
    t = theta.shape[0]
    def f(a):
        return jnp.asarray(a, jnp.float32)
    return SMPLXParams(f(theta[:, 0]), f(theta[:, 1:22]), f(theta[:, 25:40]), f(theta[:, 40:55]), f(theta[:, 22]),
                       f(theta[:, 23]), f(theta[:, 24]), f(betas), jnp.zeros((t, num_expression)), jnp.zeros((t, 3)))


def openpose_projection(model: BodyModel, params: SMPLXParams, scale, trans) -> np.ndarray:
    """The 67 OpenPose keypoints of batched ``params`` through weak-perspective cameras ``(T,)``, ``(T, 2)``:
    pixels ``(T, 67, 2)``."""
    joints = body_joints(model, params)[:, np.asarray(constants.OPENPOSE67_FROM_SMPLX)]
    return np.asarray(scale)[:, None, None] * joints[..., :2] + np.asarray(trans)[:, None, :]


def make_problem(model: BodyModel, t: int, seed: int = 0, noise_px: float = 2.0, drop: float = 0.15,
                 perturb: float = 1.0, focal_length: float | None = None) -> Synthetic:
    """``t`` frames; through a pinhole camera of ``focal_length`` (principal point the image centre) when given."""
    rng = np.random.default_rng(seed)
    theta = random_pose(rng, t)
    betas = rng.normal(0, 1.0, (t, model.num_betas)).astype(np.float32)
    scale = rng.uniform(300, 450, t).astype(np.float32)
    centre = np.array(IMAGE_SIZE, np.float32) / 2
    trans = (centre + rng.normal(0, 30, (t, 2))).astype(np.float32)
    truth = _params(theta, betas, model.num_expression)
    if focal_length is None:
        clean = openpose_projection(model, truth, scale, trans)
    else:
        truth = truth.replace(transl=jnp.asarray(np.concatenate([(trans - centre) / scale[:, None],
                                                                 focal_length / scale[:, None]], 1)))
        joints = body_joints(model, truth)[:, np.asarray(constants.OPENPOSE67_FROM_SMPLX)]
        clean = focal_length * joints[..., :2] / joints[..., 2:] + centre
    keypoints = np.concatenate([clean + rng.normal(0, noise_px, clean.shape), np.ones(clean.shape[:2] + (1,))], -1)
    keypoints[rng.uniform(size=clean.shape[:2]) < drop] = 0.0
    init_theta = theta.copy()
    init_theta[:, 0] += rng.normal(0, 0.05 * perturb, (t, 3))
    init_theta[:, 1:22] += rng.normal(0, 0.12 * perturb, (t, 21, 3))
    init_theta[:, 25:55] += rng.normal(0, 0.15 * perturb, (t, 30, 3))
    init_betas = betas + rng.normal(0, 0.5 * perturb, betas.shape).astype(np.float32)
    init = _params(init_theta, init_betas, model.num_expression)
    return Synthetic(truth, scale, trans, clean, keypoints.astype(np.float32), init)


class SyntheticClip(NamedTuple):
    """One body's clip with known answers (`make_clip`), through a pinhole camera."""

    pose: np.ndarray  # (T, 55, 3) axis-angles
    betas: np.ndarray  # (B,)
    transl: np.ndarray  # (T, 3) the body's origin in the camera frame, metres
    keypoints: np.ndarray  # (T, 67, 3) exact projections, confidence 1
    directions: np.ndarray  # (T, N, 3) unit directions of `clip.BONES` in the camera frame


def make_clip(model: BodyModel, frames: int, seed: int = 0, focal_length: float = 1500.0,
              principal_point=(960.0, 540.0), fps: float = 30.0) -> SyntheticClip:
    """A body swinging its joints smoothly about the fit's default pose, within their range (knees and elbows
    bent, flat hands), turning, walking away from a pinhole camera and back (3 to 4.5 m, 0.5 m/s at most)."""
    rng = np.random.default_rng(seed)
    seconds = np.arange(frames) / fps
    base, amplitude = np.asarray(default_pose(), np.float64), np.zeros((55, 3))
    amplitude[1:22] = rng.normal(scale=0.2, size=(21, 3))
    amplitude[0, 1] = 0.3
    base[[4, 5], 0], base[18, 1], base[19, 1] = 0.6, -0.8, 0.8  # knees, elbows
    amplitude[[4, 5, 18, 19]] = 0.0
    amplitude[[4, 5], 0], amplitude[18, 1], amplitude[19, 1] = 0.3, 0.3, -0.3
    pose = base[None] + amplitude[None] * np.sin(2 * np.pi * 0.7 * seconds)[:, None, None]
    betas = rng.normal(scale=0.3, size=model.num_betas)
    transl = np.stack([0.1 * np.sin(seconds), 0.05 * np.sin(seconds), 3.0 + 1.5 * np.sin(seconds / 3)], 1)
    km = openpose_keypoint_model(model)
    x = np.asarray(jax.vmap(lambda p, t: clip.points_3d(km, p, jnp.asarray(betas, jnp.float32), t))(
        jnp.asarray(pose, jnp.float32), jnp.asarray(transl, jnp.float32)), np.float64)
    pixels = focal_length * x[..., :2] / x[..., 2:] + np.asarray(principal_point)
    keypoints = np.concatenate([pixels, np.ones(pixels.shape[:-1] + (1,))], -1)
    a, b = (np.asarray(side) for side in zip(*clip.BONES))
    directions = x[:, b] - x[:, a]
    return SyntheticClip(pose, betas, transl, keypoints, directions / np.linalg.norm(directions, axis=-1,
                                                                                     keepdims=True))
