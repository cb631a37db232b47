"""Synthetic datasets: the body model's hands and bodies in random poses over random backgrounds, exact labels.

    hands = SyntheticHands(100_000, seed=0)       # Sequence[HandSample]; hands[i] depends on (seed, i) only
    bodies = SyntheticBodies(10_000, seed=0)      # Sequence[BodySample]

Parameters of a sample come from ``np.random.default_rng((seed, i))``; its mesh from one jitted forward pass
(training reads samples in random order, so nothing is batched across indices), then it is placed in front of a
pinhole camera (focal length chosen so the subject fills a random part of the image) and rendered. Needs no files.
"""

import functools
from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Float

import smplx_jax
from smplx_jax import constants
from smplx_jax.rotations import rotvec_to_rotmat
from train.datasets import synthetic_poses as poses
from train.datasets.sample import BodySample, HandSample, box_of_joints
from train.datasets.synthetic_render import PinholeCamera, background, camera_effects, render

TRAIN_SIZE, TEST_SIZE = 100_000, 1000
_TEST_SEED_OFFSET = 1_000_003  # test seeds never meet train seeds


@functools.cache
def _default_model() -> smplx_jax.BodyModel:
    return smplx_jax.load_model(smplx_jax.default_model_path())


def _check(num: int, seed: int, image_size: int, model: smplx_jax.BodyModel) -> None:
    if num < 0:
        raise ValueError(f"num must be >= 0, got {num}")
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    if image_size < 32:
        raise ValueError(f"image_size must be >= 32, got {image_size}")
    if model.num_betas != 10:
        raise ValueError(f"model must have 10 betas (the sample schema's), got {model.num_betas}")


def _index(i: int, num: int) -> int:
    i = int(i)
    if not -num <= i < num:
        raise IndexError(f"index {i} out of range for {num} samples")
    return i % num


def _skin_color(rng: np.random.Generator) -> Float[np.ndarray, "3"]:
    """BGR, from pale to dark, slightly varied in hue."""
    t = rng.uniform()
    return (1 - t) * np.array([185.0, 205.0, 240.0]) + t * np.array([50.0, 75.0, 115.0]) + rng.normal(0, 8, 3)


def _light(rng: np.random.Generator) -> Float[np.ndarray, "3"]:
    light = rng.normal(0.0, 0.6, 3) + [0.0, -0.3, -1.0]  # mostly from the camera's side, a little from above
    return light / np.linalg.norm(light)


def _place(
    rng: np.random.Generator, vertices: Float[np.ndarray, "V 3"], size: int, fill: float, depth: float
) -> tuple[Float[np.ndarray, "3"], PinholeCamera]:
    """A translation and a camera that show ``vertices`` about ``fill * size`` pixels across at ``depth``,
    at a random place inside the image."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    extent = float(np.max(hi[:2] - lo[:2]))
    focal = fill * size * depth / extent
    half = 0.55 * fill * size
    target = rng.uniform(half, size - half, 2)
    center = np.full(2, size / 2.0)
    middle = (lo + hi) / 2
    transl = np.append(depth * (target - center) / focal - middle[:2], depth - middle[2])
    return transl, PinholeCamera(focal, center)


def _photograph(rng: np.random.Generator, size: int, camera: PinholeCamera, transl: Float[np.ndarray, "3"],
                mesh: tuple, subject: Float[np.ndarray, "V 3"], joints: Float[np.ndarray, "J 3"],
                margin: float) -> dict:
    """The fields every sample has: the image of ``mesh`` (vertices, faces, per-face colours) moved by ``transl``
    over a random background in a random light, the box of the ``subject`` vertices and the ``joints``' labels."""
    vertices, faces, colors = mesh
    image, _ = render(background(rng, size), camera, vertices + transl, faces, colors, _light(rng),
                      rng.uniform(0.25, 0.5))
    joints_3d = joints + transl
    return dict(image=camera_effects(rng, image), box=box_of_joints(camera.project(subject + transl), margin),
                joints_2d=camera.project(joints_3d).astype(np.float32), joints_3d=joints_3d.astype(np.float32))


# ------------------------------------------------------------------------------------------------ hands


class _HandParams(NamedTuple):
    is_left: bool
    wrist_rotvec: Float[np.ndarray, "3"]
    hand_pose: Float[np.ndarray, "15 3"]
    betas: Float[np.ndarray, "10"]


def _hand_params(model_arrays, seed: int, i: int) -> _HandParams:
    means, components = model_arrays
    rng = np.random.default_rng((seed, i))
    is_left = bool(rng.random() < 0.5)
    side = 0 if is_left else 1
    wrist_rotvec = poses.random_hand_orientation(rng)
    hand_pose = poses.random_hand_pose(rng, means[side], components[side])
    betas = np.clip(rng.normal(0.0, 0.8, 10), -2.0, 2.0)
    f = np.float32
    return _HandParams(is_left, wrist_rotvec.astype(f), hand_pose.astype(f), betas.astype(f))


def _forearm(joints: Float[np.ndarray, "21 3"], rng: np.random.Generator):
    """A tapered tube from inside the palm away from the fingers, so the hand does not end in a cut."""
    along = joints[0] - joints[9]
    along /= np.linalg.norm(along)
    palm = np.cross(joints[5] - joints[0], joints[17] - joints[0])
    palm /= np.linalg.norm(palm)
    side = np.cross(along, palm)
    width = 0.42 * np.linalg.norm(joints[5] - joints[17])
    angles = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    ring = np.cos(angles)[:, None] * side * width + np.sin(angles)[:, None] * palm * width * 0.7
    length = rng.uniform(0.12, 0.3)
    bend = rng.normal(0, 0.15, 3)
    near, far = -0.012 * along + ring, (along + bend) * length + 1.25 * ring
    vertices = np.concatenate([near, far, [(along + bend) * length]])
    k = np.arange(16)
    quads = np.stack([k, (k + 1) % 16, 16 + (k + 1) % 16, 16 + k], axis=1)
    faces = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]], np.stack([16 + k, 16 + (k + 1) % 16,
                                                                               np.full(16, 32)], axis=1)])
    tri = vertices[faces]
    outward = tri.mean(axis=1) - vertices[32] / 2
    flip = np.einsum("ij,ij->i", np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), outward) < 0
    faces[flip] = faces[flip][:, ::-1]
    return vertices, faces


@jax.jit
def _hand_forward(hand: smplx_jax.HandModel, wrist_rotvec, hand_pose, betas) -> smplx_jax.HandOutput:
    return smplx_jax.hand_forward(hand, rotvec_to_rotmat(wrist_rotvec), hand_pose, betas)


class SyntheticHands(Sequence):  # of HandSample; Sequence[HandSample] would make runtime checkers load one
    """``num`` rendered hands (left or right at random): `HandSample`s with exact labels."""

    def __init__(self, num: int, seed: int, *, image_size: int = 256, model: smplx_jax.BodyModel | None = None):
        model = _default_model() if model is None else model
        _check(num, seed, image_size, model)
        self.num, self.seed, self.image_size = num, seed, image_size
        self._pca = (np.asarray(model.hand_mean, np.float64), np.asarray(model.hand_components, np.float64))
        self._hands = (smplx_jax.hand_model(model, "left"), smplx_jax.hand_model(model, "right"))
        self._faces = tuple(np.asarray(h.faces) for h in self._hands)

    def __len__(self) -> int:
        return self.num

    def params(self, i: int) -> _HandParams:
        return _hand_params(self._pca, self.seed, _index(i, self.num))

    def __getitem__(self, i: int) -> HandSample:
        i = _index(i, self.num)
        p = _hand_params(self._pca, self.seed, i)
        side = 0 if p.is_left else 1
        out = _hand_forward(self._hands[side], p.wrist_rotvec, p.hand_pose, p.betas)
        vertices, joints = np.asarray(out.vertices, np.float64), np.asarray(out.joints, np.float64)
        rng = np.random.default_rng((self.seed, i, 1))
        size = self.image_size
        transl, camera = _place(rng, vertices, size, rng.uniform(0.3, 0.7), rng.uniform(0.3, 0.8))
        arm_vertices, arm_faces = _forearm(joints, rng)
        hand_faces = self._faces[side]
        skin = _skin_color(rng)
        arm_color = skin if rng.random() < 0.5 else rng.uniform(20, 235, 3)
        colors = np.concatenate([np.repeat(skin[None], len(hand_faces), 0), np.repeat(arm_color[None], 48, 0)])
        colors *= rng.uniform(0.96, 1.04, (len(colors), 1))
        mesh = (np.concatenate([vertices, arm_vertices]), np.concatenate([hand_faces, arm_faces + len(vertices)]),
                colors)
        return HandSample(**_photograph(rng, size, camera, transl, mesh, vertices, joints, 0.05),
                          wrist_rotvec=p.wrist_rotvec, hand_pose=p.hand_pose, betas=p.betas, is_left=p.is_left)


# ------------------------------------------------------------------------------------------------ bodies


class _BodyParams(NamedTuple):
    global_orient: Float[np.ndarray, "3"]
    body_pose: Float[np.ndarray, "21 3"]
    betas: Float[np.ndarray, "10"]


def _body_params(seed: int, i: int) -> _BodyParams:
    rng = np.random.default_rng((seed, i))
    orient = poses.random_body_orientation(rng)
    body_pose = poses.random_body_pose(rng)
    betas = np.clip(rng.normal(0.0, 1.0, 10), -2.5, 2.5)
    f = np.float32
    return _BodyParams(orient.astype(f), body_pose.astype(f), betas.astype(f))


def _face_regions(model: smplx_jax.BodyModel) -> np.ndarray:
    """Per face, what covers it: 0 skin, 1 shirt, 2 sleeve (upper arm skin or shirt), 3 trousers,
    4 trouser leg below the knee, 5 shoe, from the dominant joint of its first vertex."""
    region_of_joint = np.zeros(constants.NUM_JOINTS, np.int64)
    j = {name: k for k, name in enumerate(constants.JOINT_NAMES)}
    for name in ("spine1", "spine2", "spine3", "left_collar", "right_collar", "left_shoulder", "right_shoulder"):
        region_of_joint[j[name]] = 1
    for name in ("left_elbow", "right_elbow"):
        region_of_joint[j[name]] = 2
    for name in ("pelvis", "left_hip", "right_hip"):
        region_of_joint[j[name]] = 3
    for name in ("left_knee", "right_knee", "left_ankle", "right_ankle"):
        region_of_joint[j[name]] = 4
    for name in ("left_foot", "right_foot"):
        region_of_joint[j[name]] = 5
    dominant = np.argmax(np.asarray(model.weights), axis=1)
    return region_of_joint[dominant[np.asarray(model.faces)[:, 0]]]


@jax.jit
def _body_forward(model: smplx_jax.BodyModel, global_orient, body_pose, betas):
    """Vertices and BODY_25 joints, hands at the model's mean pose."""
    params = smplx_jax.SMPLXParams.zeros(model.num_betas, model.num_expression, global_orient.dtype).replace(
        global_orient=global_orient, body_pose=body_pose, betas=betas,
        left_hand_pose=model.hand_mean[0].reshape(15, 3), right_hand_pose=model.hand_mean[1].reshape(15, 3))
    out = smplx_jax.forward(model, params)
    return out.vertices, out.joints[jnp.array(constants.BODY25_FROM_SMPLX)]


class SyntheticBodies(Sequence):  # of BodySample; Sequence[BodySample] would make runtime checkers load one
    """``num`` rendered people: `BodySample`s with exact labels; hands at the model's mean pose."""

    def __init__(self, num: int, seed: int, *, image_size: int = 256, model: smplx_jax.BodyModel | None = None):
        model = _default_model() if model is None else model
        _check(num, seed, image_size, model)
        self.num, self.seed, self.image_size = num, seed, image_size
        self._model = model
        self._faces = np.asarray(model.faces)
        self._regions = _face_regions(model)

    def __len__(self) -> int:
        return self.num

    def params(self, i: int) -> _BodyParams:
        return _body_params(self.seed, _index(i, self.num))

    def __getitem__(self, i: int) -> BodySample:
        i = _index(i, self.num)
        p = _body_params(self.seed, i)
        vertices, joints = (np.asarray(a, np.float64) for a in _body_forward(self._model, *p))
        rng = np.random.default_rng((self.seed, i, 1))
        size = self.image_size
        transl, camera = _place(rng, vertices, size, rng.uniform(0.5, 0.9), rng.uniform(2.0, 6.0))
        skin, shirt, trousers, shoes = _skin_color(rng), *rng.uniform(15, 240, (3, 3))
        sleeve = skin if rng.random() < 0.4 else shirt
        lower_leg = skin if rng.random() < 0.3 else trousers
        palette = np.stack([skin, shirt, sleeve, trousers, lower_leg, shoes])
        colors = palette[self._regions] * rng.uniform(0.96, 1.04, (len(self._regions), 1))
        return BodySample(**_photograph(rng, size, camera, transl, (vertices, self._faces, colors), vertices, joints,
                                        0.03), global_orient=p.global_orient, body_pose=p.body_pose, betas=p.betas)


def read_hands(root: Path | None, split: str) -> SyntheticHands:
    """The registry's reader: ``split`` "train" (100k) or "test" (1k, disjoint seeds); ``root`` is unused."""
    if split not in ("train", "test"):
        raise ValueError(f"split must be 'train' or 'test', got {split!r}")
    return SyntheticHands(TRAIN_SIZE, 0) if split == "train" else SyntheticHands(TEST_SIZE, _TEST_SEED_OFFSET)


def read_bodies(root: Path | None, split: str) -> SyntheticBodies:
    """As `read_hands`, for people."""
    if split not in ("train", "test"):
        raise ValueError(f"split must be 'train' or 'test', got {split!r}")
    return SyntheticBodies(TRAIN_SIZE, 0) if split == "train" else SyntheticBodies(TEST_SIZE, _TEST_SEED_OFFSET)
