"""The synthetic datasets: exact labels, determinism, schema, and renders that show what the labels say."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smplx_jax
from conftest import load
from smplx_jax import constants
from smplx_jax.rotations import rotmat_to_rotvec, rotvec_to_rotmat
from train.datasets import synthetic_poses
from train.datasets.sample import NUM_BODY_JOINTS, NUM_HAND_JOINTS, BodySample, HandSample
from train.datasets.synthetic import SyntheticBodies, SyntheticHands, read_bodies, read_hands
from train.datasets.synthetic_render import PinholeCamera, render

SIZE = 160


@pytest.fixture(scope="module")
def model(default_model_dir):
    return load(default_model_dir)


@pytest.fixture(scope="module")
def hands(model):
    return SyntheticHands(300, seed=3, image_size=SIZE, model=model)


@pytest.fixture(scope="module")
def bodies(model):
    return SyntheticBodies(70, seed=3, image_size=SIZE, model=model)


def _pinhole(joints_2d, joints_3d, size) -> tuple[PinholeCamera, float]:
    """The focal length that best maps 3D to 2D with the principal point at the image centre, and the worst
    residual in pixels: ~0 only if the 2D labels are a pinhole projection of the 3D ones."""
    centre = np.full(2, size / 2)
    ray = (joints_3d[:, :2] / joints_3d[:, 2:]).ravel()
    focal = float(ray @ (joints_2d - centre).ravel() / (ray @ ray))
    camera = PinholeCamera(focal, centre)
    return camera, float(np.abs(camera.project(joints_3d) - joints_2d).max())


def _check_schema(sample, num_joints, pose_fields):
    assert sample.image.dtype == np.uint8 and sample.image.shape == (SIZE, SIZE, 3)
    for name, shape in [("box", (4,)), ("joints_2d", (num_joints, 2)), ("joints_3d", (num_joints, 3)),
                        ("betas", (10,))] + pose_fields:
        value = getattr(sample, name)
        assert value.dtype == np.float32 and value.shape == shape, name
        assert np.all(np.isfinite(value)), name
    x, y, w, h = sample.box
    inside = (sample.joints_2d >= [x, y]) & (sample.joints_2d <= [x + w, y + h])
    assert np.all(inside)
    assert np.all(sample.joints_3d[:, 2] > 0)


def _labels_cover(image_mask, joints_2d) -> float:
    """Share of the joints inside the image that fall on (or next to) covered pixels."""
    size = image_mask.shape[0]
    pixel = np.floor(joints_2d).astype(int)
    inside = np.all((pixel >= 1) & (pixel < size - 1), axis=1)
    near = [image_mask[y - 1:y + 2, x - 1:x + 2].any() for x, y in pixel[inside]]
    return float(np.mean(near)) if near else 1.0


def test_hand_labels_are_exact(hands, model):
    sides = set()
    for i in (0, 1, 2, 257, 299):
        s = hands[i]
        assert isinstance(s, HandSample)
        _check_schema(s, NUM_HAND_JOINTS, [("wrist_rotvec", (3,)), ("hand_pose", (15, 3))])
        camera, residual = _pinhole(s.joints_2d, s.joints_3d, SIZE)
        assert residual < 1e-3
        hand = smplx_jax.hand_model(model, "left" if s.is_left else "right")
        wrist_rotmat = rotvec_to_rotmat(jnp.asarray(s.wrist_rotvec))
        out = jax.jit(smplx_jax.hand_forward)(hand, wrist_rotmat, jnp.asarray(s.hand_pose), jnp.asarray(s.betas))
        np.testing.assert_allclose(np.asarray(out.joints) + s.joints_3d[0], s.joints_3d, atol=1e-5)
        # the mesh these labels describe covers the labelled joints and lies in the box
        vertices = np.asarray(out.vertices) + s.joints_3d[0]
        faces = np.asarray(hand.faces)
        _, mask = render(np.zeros((SIZE, SIZE, 3), np.uint8), camera, vertices, faces,
                         np.full((len(faces), 3), 200.0), np.array([0.0, 0.0, -1.0]), 0.5)
        assert mask.mean() > 0.03
        assert _labels_cover(mask, s.joints_2d) >= 0.8
        x, y, w, h = s.box
        projected = camera.project(vertices)
        assert np.all((projected >= [x - 1e-3, y - 1e-3]) & (projected <= [x + w + 1e-3, y + h + 1e-3]))
        sides.add(s.is_left)
    assert sides == {True, False}


def test_hand_poses_vary_and_stay_anatomical(hands):
    params = [hands.params(i) for i in range(64)]
    poses = np.stack([p.hand_pose for p in params])
    assert np.all(np.linalg.norm(poses, axis=-1) <= 1.8 + 1e-5)
    assert poses.std(axis=0).mean() > 0.1  # not one pose
    mean = rotvec_to_rotmat(jnp.asarray(synthetic_poses.HAND_MEAN_ROTVEC))
    wrists = rotvec_to_rotmat(jnp.stack([p.wrist_rotvec for p in params]))
    turns = np.linalg.norm(rotmat_to_rotvec(wrists @ mean.T), axis=-1)  # between each wrist and the mean one
    assert max(turns) <= synthetic_poses.HAND_MAX_TURN + 1e-5 and max(turns) > 1.0 and min(turns) < 0.5


def test_samples_are_deterministic(hands, model):
    first = hands[7]
    fresh = SyntheticHands(300, seed=3, image_size=SIZE, model=model)
    fresh[260]  # another sample first
    again = fresh[7]
    for name in HandSample._fields:
        np.testing.assert_array_equal(getattr(first, name), getattr(again, name), err_msg=name)
    other_seed = SyntheticHands(300, seed=4, image_size=SIZE, model=model)
    assert not np.array_equal(other_seed.params(7).hand_pose, hands.params(7).hand_pose)
    assert hands[-1].joints_2d.tolist() == hands[299].joints_2d.tolist()
    with pytest.raises(IndexError):
        hands[300]


def test_body_labels_are_exact(bodies, model):
    rest = smplx_jax.SMPLXParams.zeros().replace(left_hand_pose=model.hand_mean[0].reshape(15, 3),
                                                 right_hand_pose=model.hand_mean[1].reshape(15, 3))
    for i in (0, 5, 69):
        s = bodies[i]
        assert isinstance(s, BodySample)
        _check_schema(s, NUM_BODY_JOINTS, [("global_orient", (3,)), ("body_pose", (21, 3))])
        camera, residual = _pinhole(s.joints_2d, s.joints_3d, SIZE)
        assert residual < 1e-3
        params = rest.replace(global_orient=jnp.asarray(s.global_orient), body_pose=jnp.asarray(s.body_pose),
                              betas=jnp.asarray(s.betas))
        out = jax.jit(smplx_jax.forward)(model, params)
        joints = np.asarray(out.joints)[list(constants.BODY25_FROM_SMPLX)]
        pelvis = 8  # BODY_25 mid-hip = SMPL-X pelvis
        np.testing.assert_allclose(joints - joints[pelvis], s.joints_3d - s.joints_3d[pelvis], atol=1e-5)
        # upright: the head is above the pelvis in the image (y down) for almost every sample
        assert s.joints_3d[0, 1] < s.joints_3d[pelvis, 1]
        vertices = np.asarray(out.vertices) - joints[pelvis] + s.joints_3d[pelvis]
        faces = np.asarray(model.faces)
        _, mask = render(np.zeros((SIZE, SIZE, 3), np.uint8), camera, vertices, faces,
                         np.full((len(faces), 3), 200.0), np.array([0.0, 0.0, -1.0]), 0.5)
        assert _labels_cover(mask, s.joints_2d) >= 0.8


def test_bodies_are_deterministic(bodies, model):
    first = bodies[3]
    fresh = SyntheticBodies(70, seed=3, image_size=SIZE, model=model)
    fresh[65]
    again = fresh[3]
    for name in BodySample._fields:
        np.testing.assert_array_equal(getattr(first, name), getattr(again, name), err_msg=name)


def test_readers_split_and_validate(model):
    train, test = read_hands(None, "train"), read_hands(None, "test")
    assert len(train) > 10 * len(test) > 0 and train.seed != test.seed
    assert not np.array_equal(train.params(0).hand_pose, test.params(0).hand_pose)
    assert read_bodies(None, "test").seed == test.seed
    with pytest.raises(ValueError, match="split"):
        read_hands(None, "val")
    with pytest.raises(ValueError, match="num"):
        SyntheticHands(-1, 0, model=model)
    with pytest.raises(ValueError, match="image_size"):
        SyntheticBodies(1, 0, image_size=8, model=model)
