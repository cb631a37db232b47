"""Rotation conversions: round trips, agreement with Rodrigues' formula, finite exact gradients at zero."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from params_util import random_rotvecs
from smplx_jax import rotations as rot

ROTVECS = random_rotvecs(np.random.default_rng(0), (400,), max_angle=np.pi - 1e-3).astype(np.float32)


def _is_rotation(r, atol=1e-5):
    eye = np.broadcast_to(np.eye(3), r.shape)
    return np.allclose(np.swapaxes(r, -1, -2) @ r, eye, atol=atol) and np.allclose(np.linalg.det(r), 1, atol=atol)


def test_rotvec_rotmat_round_trip():
    r = np.asarray(rot.rotvec_to_rotmat(ROTVECS))
    assert _is_rotation(r)
    np.testing.assert_allclose(np.asarray(rot.rotmat_to_rotvec(r)), ROTVECS, atol=2e-4)


def test_rotvec_to_rotmat_matches_matrix_exponential():
    k = np.zeros((len(ROTVECS), 3, 3))
    x, y, z = ROTVECS.astype(np.float64).T
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -z, y, -x
    k -= np.swapaxes(k, 1, 2)
    expm = np.eye(3) + k  # Taylor series of exp(K) to convergence
    term = k.copy()
    for n in range(2, 40):
        term = term @ k / n
        expm = expm + term
    np.testing.assert_allclose(np.asarray(rot.rotvec_to_rotmat(ROTVECS)), expm, atol=2e-6)


def test_quaternion_round_trips():
    q = np.asarray(rot.rotvec_to_quat(ROTVECS))
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1, atol=1e-6)
    np.testing.assert_allclose(np.asarray(rot.quat_to_rotmat(q)), np.asarray(rot.rotvec_to_rotmat(ROTVECS)), atol=2e-6)
    np.testing.assert_allclose(np.asarray(rot.quat_to_rotvec(q)), ROTVECS, atol=2e-5)
    np.testing.assert_allclose(np.asarray(rot.rotmat_to_quat(rot.quat_to_rotmat(q))), q, atol=2e-6)


def test_rot6d_round_trip_and_gram_schmidt():
    r = np.asarray(rot.rotvec_to_rotmat(ROTVECS))
    np.testing.assert_allclose(np.asarray(rot.rot6d_to_rotmat(rot.rotmat_to_rot6d(r))), r, atol=2e-6)
    # Any 6 numbers give a rotation whose first column is the normalised first column of the 3x2 reading.
    raw = np.random.default_rng(1).normal(size=(50, 6)).astype(np.float32)
    out = np.asarray(rot.rot6d_to_rotmat(raw))
    assert _is_rotation(out)
    first = raw.reshape(50, 3, 2)[:, :, 0]
    np.testing.assert_allclose(out[:, :, 0], first / np.linalg.norm(first, axis=1, keepdims=True), atol=1e-6)


@pytest.mark.parametrize("fn, at", [
    (rot.rotvec_to_rotmat, np.zeros(3)),
    (rot.rotvec_to_quat, np.zeros(3)),
    (rot.rotmat_to_rotvec, np.eye(3)),
    (rot.rotmat_to_quat, np.eye(3)),
    (rot.quat_to_rotvec, np.array([1.0, 0, 0, 0])),
], ids=["rotvec_to_rotmat", "rotvec_to_quat", "rotmat_to_rotvec", "rotmat_to_quat", "quat_to_rotvec"])
def test_jacobian_finite_and_exact_at_identity(fn, at):
    with jax.enable_x64(True):
        x = jnp.asarray(at, jnp.float64)
        jac = np.asarray(jax.jacfwd(fn)(x))
        jac_rev = np.asarray(jax.jacrev(fn)(x))
        assert np.all(np.isfinite(jac)) and np.all(np.isfinite(jac_rev))
        np.testing.assert_allclose(jac, jac_rev, atol=1e-12)
        flat = x.reshape(-1)
        eps = 1e-6
        for i in range(flat.size):
            step = jnp.zeros_like(flat).at[i].set(eps).reshape(x.shape)
            numeric = (fn(x + step) - fn(x - step)) / (2 * eps)
            np.testing.assert_allclose(jac.reshape(jac.shape[: jac.ndim - x.ndim] + (-1,))[..., i], numeric, atol=1e-8)


def test_rotvec_to_rotmat_derivative_at_zero_is_the_generator():
    """d R / d r_x at r = 0 is the skew generator of x."""
    jac = np.asarray(jax.jacfwd(rot.rotvec_to_rotmat)(jnp.zeros(3)))
    np.testing.assert_allclose(jac[..., 0], [[0, 0, 0], [0, 0, -1], [0, 1, 0]], atol=1e-7)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=3, max_size=3))
def test_rotmat_to_rotvec_inverts_small_and_large_angles(v):
    v = np.asarray(v, np.float64)
    angle = np.linalg.norm(v)
    if angle > np.pi - 1e-2:
        v = v / angle * (np.pi - 1e-2)
    with jax.enable_x64(True):
        back = np.asarray(rot.rotmat_to_rotvec(rot.rotvec_to_rotmat(jnp.asarray(v))))
    np.testing.assert_allclose(back, v, atol=1e-9)


def test_rotmat_to_rotvec_at_half_turn():
    """Angle pi: the axis is recovered up to sign."""
    axis = np.array([0.3, -0.4, 0.5]) / np.linalg.norm([0.3, -0.4, 0.5])
    with jax.enable_x64(True):
        back = np.asarray(rot.rotmat_to_rotvec(rot.rotvec_to_rotmat(jnp.asarray(axis * np.pi))))
    assert np.allclose(back, axis * np.pi, atol=1e-7) or np.allclose(back, -axis * np.pi, atol=1e-7)
