"""train.losses: each term against hand-computed values on constructed cases, masks, gradients, jit."""

import inspect

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smplx_jax
from conftest import jit_fast_compile, load
from jaxmocap.regressors import BodyOutput, crops
from smplx_jax.constants import BODY25_FROM_SMPLX
from smplx_jax.default_model import default_model_path
from smplx_jax.rotations import rotvec_to_rotmat
from train.datasets.sample import BodyExample, HandExample
from train.losses import (
    BodyLossWeights,
    HandLossWeights,
    body_joints,
    body_losses,
    hand_crop_joints,
    hand_losses,
    right_hand_joints,
)

# One compiled function each, for values and gradients: ((total, terms), gradient of total).
_hand = jit_fast_compile(jax.value_and_grad(lambda raw, m, h, ex: _with_terms(hand_losses(m, h, raw, ex)),
                                            has_aux=True))
_body = jit_fast_compile(jax.value_and_grad(lambda out, m, ex, w: _with_terms(body_losses(m, out, ex, w)),
                                            has_aux=True))
_body_joints = jax.jit(body_joints)


def _with_terms(terms):
    return terms["total"], terms


def _hand_losses(model, right_hand, raw, example):
    return _hand(raw, model, right_hand, example)[0][1]


def _hand_grad(raw, model, right_hand, example):
    return _hand(raw, model, right_hand, example)[1]


def _body_losses(model, output, example, weights=BodyLossWeights()):
    return _body(output, model, example, weights)[0][1]


def _body_grad(output, model, example):
    return _body(output, model, example, BodyLossWeights())[1]


@pytest.fixture(scope="module")
def model():
    return load(default_model_path().parent.parent)


@pytest.fixture(scope="module")
def right_hand(model):
    return smplx_jax.hand_model(model, "right")


@pytest.fixture(scope="module")
def hand_case(model, right_hand):
    """A raw prediction and an example labelled from exactly that prediction (every term but shape is 0)."""
    rng = np.random.default_rng(0)
    relative = 0.3 * rng.normal(size=(16, 3))
    betas = np.zeros(10)
    camera = np.array([6.0, 0.02, -0.03])
    raw = jnp.asarray(np.concatenate([camera, relative.ravel(), betas]), jnp.float32)
    joints = np.asarray(jax.jit(right_hand_joints)(model, right_hand, raw))
    crop = (joints[:, :2] - joints[5, :2] + camera[1:]) * camera[0]  # the weak perspective, written out
    absolute = relative[1:] + np.asarray(model.hand_mean[1]).reshape(15, 3)
    example = HandExample(
        image=np.zeros((8, 8, 3), np.float32), joints_2d=crop.astype(np.float32), joints_2d_mask=np.ones(21, bool),
        joints_3d=(joints + [0.1, -0.2, 0.6]).astype(np.float32), joints_3d_mask=np.array(True),
        pose=np.concatenate([relative[:1], absolute]).astype(np.float32), pose_mask=np.array(True),
        betas=np.zeros(10, np.float32), betas_mask=np.array(True))
    return raw, example, joints


def test_hand_terms_zero_at_the_label(model, right_hand, hand_case):
    raw, example, _ = hand_case
    terms = _hand_losses(model, right_hand, raw, example)
    for name in ("pose", "joints_3d", "joints_2d", "shape", "total"):
        assert abs(float(terms[name])) < 1e-9, name


def test_hand_pose_term(model, right_hand, hand_case):
    raw, example, _ = hand_case
    terms = _hand_losses(model, right_hand, raw.at[3 + 7].add(0.2).at[3 + 40].add(-0.1), example)
    np.testing.assert_allclose(terms["pose"], (0.2**2 + 0.1**2) / 48, rtol=1e-4)


def test_hand_3d_term_rescales_the_label_by_the_middle_knuckle(model, right_hand, hand_case):
    raw, example, joints = hand_case
    offset = np.zeros((21, 3))
    offset[12] = [0.003, -0.004, 0.0]  # middle fingertip: not on the knuckle, so the scale is untouched
    label = 2.5 * (joints + offset) + [0.3, 0.1, 0.9]  # a hand 2.5 times larger, elsewhere in the camera frame
    terms = _hand_losses(model, right_hand, raw, example._replace(joints_3d=label.astype(np.float32)))
    np.testing.assert_allclose(terms["joints_3d"], 0.005**2 / 63, rtol=1e-3)


def test_hand_2d_term_is_the_squared_offset_on_visible_joints(model, right_hand, hand_case):
    raw, example, _ = hand_case
    offset = np.zeros((21, 2), np.float32)
    offset[:, 0], offset[:, 1] = 0.03, -0.04
    mask = np.ones(21, bool)
    mask[[0, 4, 20]] = False
    shifted = example._replace(joints_2d=example.joints_2d + offset, joints_2d_mask=mask)
    terms = _hand_losses(model, right_hand, raw, shifted)
    np.testing.assert_allclose(terms["joints_2d"], 18 * (0.03**2 + 0.04**2) / 42, rtol=1e-4)


def test_hand_crop_projection_is_the_inference_one(hand_case):
    """hand_crop_joints maps to the same pixels as crops.hand_to_image on a 224-pixel window at the origin."""
    raw, _, joints = hand_case
    window = crops.Window(np.zeros((1, 2), int), np.full((1, 2), 224), np.array([[0, 0, 224, 224]]), np.ones(1, bool))
    camera = np.asarray(raw[:3])
    pixels = crops.hand_to_image(jnp.asarray(joints - joints[5])[None], jnp.asarray(camera)[None], window)[0]
    np.testing.assert_allclose((hand_crop_joints(jnp.asarray(joints), jnp.asarray(camera)) + 1) * 112, pixels,
                               atol=1e-3)


def test_hand_shape_and_total(model, right_hand, hand_case):
    raw, example, _ = hand_case
    betas = np.array([0.5, -1.0, 0, 0, 0, 0, 0, 0, 0, 2.0])
    raw = raw.at[3 + 7].add(0.2).at[51:].set(betas)
    terms = _hand_losses(model, right_hand, raw, example)
    np.testing.assert_allclose(terms["shape"], 0.25 + 1 + 4, rtol=1e-6)
    expected = 10 * terms["pose"] + 100 * terms["joints_3d"] + 10 * terms["joints_2d"] + 0.1 * terms["shape"]
    np.testing.assert_allclose(terms["total"], expected, rtol=1e-6)
    assert float(terms["joints_3d"]) > 0  # betas change the hand


def test_hand_masks_off_give_zero_and_finite_gradients(model, right_hand, hand_case):
    raw, example, _ = hand_case
    zeros = example._replace(
        joints_2d=np.zeros((21, 2), np.float32), joints_2d_mask=np.zeros(21, bool),
        joints_3d=np.zeros((21, 3), np.float32), joints_3d_mask=np.array(False),
        pose=np.zeros((16, 3), np.float32), pose_mask=np.array(False))
    flat = jnp.zeros(61).at[0].set(5.0)  # zero pose: the identity, where rotations are most delicate
    for prediction in (raw, flat):
        terms = _hand_losses(model, right_hand, prediction, zeros)
        for name in ("pose", "joints_3d", "joints_2d"):
            assert float(terms[name]) == 0.0, name
        assert np.all(np.isfinite(_hand_grad(prediction, model, right_hand, zeros)))
    assert np.all(np.isfinite(_hand_grad(flat, model, right_hand, example)))


def test_hand_jit_equals_eager(model, right_hand, hand_case):
    raw, example, _ = hand_case
    raw = raw.at[5].add(0.1).at[52].set(0.7)
    eager, jitted = hand_losses(model, right_hand, raw, example), _hand_losses(model, right_hand, raw, example)
    for name in eager:
        np.testing.assert_allclose(eager[name], jitted[name], rtol=1e-5, atol=1e-9)


def test_hand_rejects_a_batch(model, right_hand, hand_case):
    raw, example, _ = hand_case
    # hand_losses' own check: unwrapped, since in the test run the annotation's check refuses the shape first
    with pytest.raises(ValueError, match="raw"):
        inspect.unwrap(hand_losses)(model, right_hand, raw[None], example)


@pytest.fixture(scope="module")
def body_case(model):
    rng = np.random.default_rng(1)
    pose = 0.3 * rng.normal(size=(22, 3))
    rotmats = np.concatenate([np.asarray(rotvec_to_rotmat(jnp.asarray(pose))), np.tile(np.eye(3), (2, 1, 1))])
    betas = rng.normal(size=10)
    output = BodyOutput(jnp.asarray(rotmats, jnp.float32), jnp.asarray(betas, jnp.float32),
                        jnp.array([0.9, 0.05, -0.1], jnp.float32))
    params = smplx_jax.SMPLXParams.zeros().replace(
        global_orient=jnp.asarray(pose[0], jnp.float32), body_pose=jnp.asarray(pose[1:], jnp.float32),
        left_hand_pose=model.hand_mean[0].reshape(15, 3), right_hand_pose=model.hand_mean[1].reshape(15, 3),
        betas=jnp.asarray(betas, jnp.float32))
    joints = np.asarray(jax.jit(smplx_jax.forward_joints)(model, params))[np.array(BODY25_FROM_SMPLX)]
    window = crops.Window(np.zeros((1, 2), int), np.full((1, 2), 224), np.array([[0, 0, 224, 224]]), np.ones(1, bool))
    crop = np.asarray(crops.body_to_image(jnp.asarray(joints)[None], output.camera[None], window))[0] / 112 - 1
    example = BodyExample(
        image=np.zeros((8, 8, 3), np.float32), joints_2d=crop.astype(np.float32), joints_2d_mask=np.ones(25, bool),
        joints_3d=(joints + [0.2, 0.3, 4.0]).astype(np.float32), joints_3d_mask=np.array(True),
        pose=pose.astype(np.float32), pose_mask=np.array(True), betas=betas.astype(np.float32),
        betas_mask=np.array(True))
    return output, example, joints


def test_body_joints_match_smplx_forward(model, body_case):
    output, _, joints = body_case
    np.testing.assert_allclose(_body_joints(model, output), joints, atol=1e-5)


def test_body_terms_zero_at_the_label_but_camera(model, body_case):
    output, example, _ = body_case
    terms = _body_losses(model, output, example)
    for name in ("pose", "betas", "joints_3d", "joints_2d"):
        assert abs(float(terms[name])) < 1e-8, name
    np.testing.assert_allclose(terms["camera"], np.exp(-9.0) ** 2, rtol=1e-5)
    np.testing.assert_allclose(terms["shape"], np.sum(np.asarray(output.betas) ** 2), rtol=1e-5)
    np.testing.assert_allclose(terms["total"], 60 * (terms["camera"] + 0.001 * terms["betas"]), rtol=1e-3)


def test_body_terms_by_hand(model, body_case):
    output, example, _ = body_case
    bent = output.rotmats.at[3].set(jnp.eye(3))
    label = np.array(example.joints_3d)
    label[4] += [0.01, 0.0, -0.02]
    crop = np.array(example.joints_2d)
    crop[:, 0] += 0.05
    mask = np.ones(25, bool)
    mask[[1, 2]] = False
    changed = example._replace(betas=example.betas + np.eye(10, dtype=np.float32)[2] * 0.3, joints_3d=label,
                               joints_2d=crop, joints_2d_mask=mask)
    terms = _body_losses(model, output._replace(rotmats=bent), changed)
    np.testing.assert_allclose(terms["pose"], np.sum((np.asarray(output.rotmats[3]) - np.eye(3)) ** 2) / 198,
                               rtol=1e-4)
    np.testing.assert_allclose(terms["betas"], 0.09 / 10, rtol=1e-4)
    assert float(terms["joints_3d"]) > 0
    terms = _body_losses(model, output, changed)
    np.testing.assert_allclose(terms["joints_3d"], (0.01**2 + 0.02**2) / 75, rtol=1e-3)
    np.testing.assert_allclose(terms["joints_2d"], 23 * 0.05**2 / 50, rtol=1e-3)
    w = BodyLossWeights()
    expected = w.overall * sum(getattr(w, k) * terms[k] for k in ("pose", "betas", "joints_3d", "joints_2d",
                                                                   "camera", "shape"))
    np.testing.assert_allclose(terms["total"], expected, rtol=1e-6)


def test_body_masks_off_give_zero_and_finite_gradients(model, body_case):
    output, example, _ = body_case
    zeros = example._replace(
        joints_2d=np.zeros((25, 2), np.float32), joints_2d_mask=np.zeros(25, bool),
        joints_3d=np.zeros((25, 3), np.float32), joints_3d_mask=np.array(False),
        pose=np.zeros((22, 3), np.float32), pose_mask=np.array(False), betas_mask=np.array(False))
    rest = BodyOutput(jnp.tile(jnp.eye(3), (24, 1, 1)), jnp.zeros(10), jnp.array([1.0, 0.0, 0.0]))
    for prediction in (output, rest):
        terms = _body_losses(model, prediction, zeros)
        for name in ("pose", "betas", "joints_3d", "joints_2d"):
            assert float(terms[name]) == 0.0, name
        grads = _body_grad(prediction, model, zeros)
        assert all(np.all(np.isfinite(g)) for g in jax.tree.leaves(grads))
    grads = _body_grad(rest, model, example)
    assert all(np.all(np.isfinite(g)) for g in jax.tree.leaves(grads))


def test_body_weights(model, body_case):
    output, example, _ = body_case
    jitted = _body_losses(model, output, example, BodyLossWeights(shape=0.5, overall=1.0))
    np.testing.assert_allclose(jitted["total"], jitted["camera"] + 0.5 * jitted["shape"] + 0.001 * jitted["betas"]
                               + jitted["pose"] + 5 * (jitted["joints_3d"] + jitted["joints_2d"]), rtol=1e-6)
    assert HandLossWeights() == (10.0, 100.0, 10.0, 0.1)
