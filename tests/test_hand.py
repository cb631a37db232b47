"""The hand model H against the whole body."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smplx_jax
from conftest import load
from params_util import random_params
from smplx_jax import constants
from smplx_jax.hand import hand_forward, hand_model

SIDES = {"left": (constants.LEFT_WRIST, constants.LEFT_HAND21_FROM_SMPLX),
         "right": (constants.RIGHT_WRIST, constants.RIGHT_HAND21_FROM_SMPLX)}


@pytest.fixture(scope="module", params=["left", "right"])
def hand_setup(request, default_model_dir):
    model = load(default_model_dir)
    return request.param, model, hand_model(model, request.param)


def _compare(model, hand, side, params):
    wrist, openpose_ids = SIDES[side]
    body = smplx_jax.forward(model, params)
    skeleton = smplx_jax.posed_skeleton(model, params)
    out = jax.jit(hand_forward)(hand, skeleton.glob_rotmats[wrist], getattr(params, f"{side}_hand_pose"), params.betas)
    body_hand = np.asarray(body.vertices)[np.asarray(hand.vertex_ids)] - np.asarray(skeleton.joints[wrist])
    body_joints = np.asarray(body.joints)[np.asarray(openpose_ids)] - np.asarray(skeleton.joints[wrist])
    return np.asarray(out.vertices), body_hand, np.asarray(out.joints), body_joints


def test_subset_is_the_hand(hand_setup):
    side, model, hand = hand_setup
    wrist, _ = SIDES[side]
    tips = constants.VERTEX_JOINT_IDS[11:16] if side == "left" else constants.VERTEX_JOINT_IDS[16:21]
    assert set(tips) <= set(np.asarray(hand.vertex_ids).tolist())
    dominant = np.argmax(np.asarray(model.weights)[np.asarray(hand.vertex_ids)], axis=1)
    fingers = constants.LEFT_HAND_JOINTS if side == "left" else constants.RIGHT_HAND_JOINTS
    assert np.all(np.isin(dominant, (wrist,) + fingers))
    num = hand.vertex_ids.shape[0]
    assert 300 < num < 2000 and hand.faces.shape[0] > num
    # hand vertices lie on that side of the body
    x = np.asarray(hand.template_cm)[0]
    assert np.all(x > 0.4) if side == "left" else np.all(x < -0.4)


def test_hand_forward_reproduces_the_body_hand(hand_setup):
    """Random body pose, shape and global orientation with the wrist's local rotation at rest (the forearm
    then moves rigidly with the hand, as H assumes): every hand vertex and the 21 joints agree."""
    side, model, hand = hand_setup
    wrist, _ = SIDES[side]
    for seed in range(4):
        params = jax.tree.map(lambda a: a[0], random_params(seed=20 + seed, batch=1, max_angle=1.5))
        params = params.replace(body_pose=params.body_pose.at[wrist - 1].set(0.0), expression=jnp.zeros(10))
        verts, body_verts, joints, body_joints = _compare(model, hand, side, params)
        np.testing.assert_allclose(verts, body_verts, atol=1e-5)
        np.testing.assert_allclose(joints, body_joints, atol=1e-5)


def test_hand_forward_with_a_bent_wrist(hand_setup):
    """Any wrist rotation: vertices skinned only to hand joints agree exactly; the others are the forearm
    side of the wrist and stay within a few centimetres."""
    side, model, hand = hand_setup
    wrist, _ = SIDES[side]
    params = jax.tree.map(lambda a: a[0], random_params(seed=30, batch=1, max_angle=1.5))
    params = params.replace(expression=jnp.zeros(10))
    verts, body_verts, joints, body_joints = _compare(model, hand, side, params)
    fingers = constants.LEFT_HAND_JOINTS if side == "left" else constants.RIGHT_HAND_JOINTS
    pure = np.asarray(model.weights)[np.asarray(hand.vertex_ids)][:, (wrist,) + fingers].sum(axis=1) > 1 - 1e-6
    assert pure.mean() > 0.5
    np.testing.assert_allclose(verts[pure], body_verts[pure], atol=1e-5)
    np.testing.assert_allclose(joints, body_joints, atol=1e-5)
    assert np.abs(verts - body_verts).max() < 0.05
