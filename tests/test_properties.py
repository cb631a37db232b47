"""Properties of the forward passes: jit = eager, vmap = loop, no recompilation, gradients."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smplx_jax
from conftest import jit_fast_compile, load, programs_lowered
from params_util import random_params


def _one(params, i):
    return jax.tree.map(lambda a: a[i], params)


def test_jit_equals_eager(default_model_dir):
    """Compiled against each operation run alone (``jax.disable_jit``: the public functions are jitted)."""
    model = load(default_model_dir)
    params = _one(random_params(seed=3, batch=1), 0)
    with jax.disable_jit():
        eager, eager_joints = smplx_jax.forward(model, params), smplx_jax.forward_joints(model, params)
    jitted = smplx_jax.forward(model, params)
    np.testing.assert_allclose(np.asarray(jitted.vertices), np.asarray(eager.vertices), atol=2e-6)
    np.testing.assert_allclose(np.asarray(jitted.joints), np.asarray(eager.joints), atol=2e-6)
    np.testing.assert_allclose(np.asarray(smplx_jax.forward_joints(model, params)), np.asarray(eager_joints),
                               atol=2e-6)


def test_an_eager_call_runs_one_compiled_program(default_model_dir):
    """Called outside any jit (here vmapped over a batch of 5, a shape no other test uses), a forward pass of the
    body or a hand, or a rotation conversion, lowers one program, not each of its operations, and nothing on its
    second call."""
    model = load(default_model_dir)
    params = random_params(seed=7, batch=5)
    hand_args = (smplx_jax.hand_model(model, "left"), smplx_jax.rotations.rotvec_to_rotmat(params.global_orient),
                 params.left_hand_pose, params.betas)
    calls = [functools.partial(jax.vmap(fn, in_axes=(None, 0)), model, params)
             for fn in (smplx_jax.forward_joints, smplx_jax.forward, smplx_jax.posed_skeleton)]
    calls.append(functools.partial(jax.vmap(smplx_jax.hand_forward, in_axes=(None, 0, 0, 0)), *hand_args))
    rot = smplx_jax.rotations
    rotvecs = np.asarray(params.left_hand_pose)  # (5, 15, 3)
    rotmats, quats = np.asarray(rot.rotvec_to_rotmat(rotvecs)), np.asarray(rot.rotvec_to_quat(rotvecs))
    calls += [functools.partial(fn, x[:, :7]) for fn, x in (
        (rot.rotvec_to_rotmat, rotvecs), (rot.rotvec_to_quat, rotvecs), (rot.rotmat_to_rotvec, rotmats),
        (rot.rotmat_to_quat, rotmats), (rot.rotmat_to_rot6d, rotmats), (rot.quat_to_rotvec, quats),
        (rot.quat_to_rotmat, quats), (rot.rot6d_to_rotmat, np.asarray(rot.rotmat_to_rot6d(rotmats))))]
    counts = []
    with programs_lowered() as lowered:
        for call in calls * 2:
            before = len(lowered)
            jax.block_until_ready(call())
            counts.append(len(lowered) - before)
    assert counts == [1] * len(calls) + [0] * len(calls), counts


def test_vmap_equals_loop(default_model_dir):
    model = load(default_model_dir)
    params = random_params(seed=4, batch=3)
    batched = jax.jit(jax.vmap(smplx_jax.forward_joints, in_axes=(None, 0)))(model, params)
    for i in range(3):
        alone = smplx_jax.forward_joints(model, _one(params, i))
        np.testing.assert_allclose(np.asarray(batched[i]), np.asarray(alone), atol=2e-6)


def test_second_call_does_not_recompile(default_model_dir):
    model = load(default_model_dir)
    fn = smplx_jax.forward_joints  # jitted
    fn(model, _one(random_params(seed=5, batch=1), 0))
    again = smplx_jax.load_model(default_model_dir / "smplx" / "SMPLX_NEUTRAL.npz")  # new arrays, same structure
    params = _one(random_params(seed=6, batch=1), 0)
    with programs_lowered() as lowered:
        jax.block_until_ready(fn(again, params))
    assert lowered == []


def test_output_shapes(default_model_dir):
    model = load(default_model_dir)
    out = smplx_jax.forward(model, smplx_jax.SMPLXParams.zeros())
    assert out.vertices.shape == (model.num_vertices, 3) and out.joints.shape == (127, 3)
    assert out.vertices.dtype == jnp.float32


def _loss(model, params, weights):
    return jnp.sum(smplx_jax.forward_joints(model, params) * weights)


@pytest.mark.parametrize("at_zero", [False, True], ids=["random_pose", "zero_pose"])
def test_gradients_match_finite_differences(default_model_dir, at_zero):
    """Central differences in float64 of a random linear functional of all 127 joints."""
    with jax.enable_x64(True):
        model = smplx_jax.load_model(default_model_dir / "smplx" / "SMPLX_NEUTRAL.npz", dtype=jnp.float64)
        params = jax.tree.map(lambda a: jnp.asarray(a[0], jnp.float64), random_params(seed=7, batch=1, max_angle=2.0))
        if at_zero:
            params = jax.tree.map(jnp.zeros_like, params)
        weights = jnp.asarray(np.random.default_rng(8).normal(size=(127, 3)))
        grads = jit_fast_compile(jax.grad(_loss, argnums=1))(model, params, weights)
        loss = jit_fast_compile(_loss)
        rng = np.random.default_rng(9)
        for name in ("global_orient", "body_pose", "right_hand_pose", "jaw_pose", "betas", "expression"):
            value = getattr(params, name)
            grad = np.asarray(getattr(grads, name))
            assert np.all(np.isfinite(grad)), name
            for _ in range(4):
                idx = tuple(int(rng.integers(0, n)) for n in value.shape)
                eps = 1e-6
                plus = params.replace(**{name: value.at[idx].add(eps)})
                minus = params.replace(**{name: value.at[idx].add(-eps)})
                numeric = (loss(model, plus, weights) - loss(model, minus, weights)) / (2 * eps)
                assert abs(float(numeric) - grad[idx]) <= 1e-6 * max(1.0, abs(float(numeric))), (name, idx)
