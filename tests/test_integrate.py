"""Integration: copy-and-paste, the 2D fit, IK, smoothing, motion.npz and ``jaxmocap fit``.

Jitted functions are shared at module level and every fit runs at one padded batch size (32), so the solver
compiles once for the whole file.
"""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smplx_jax
from conftest import jit_fast_compile, load
from jaxmocap.buckets import bucket_size
from jaxmocap.cli import main
from jaxmocap.integrate import (
    copy_paste,
    fit,
    fit_frame,
    fitting,
    ik,
    inverse_kinematics,
    smooth_params,
    smooth_rotvecs,
    synthetic,
)
from jaxmocap.integrate.motion_arrays import body_joints
from jaxmocap.pipeline.fit_folder import infer_image_size
from params_util import random_params
from smplx_jax import constants, rotations

T = 32  # frames per synthetic problem: one bucket


@pytest.fixture(scope="module")
def model(default_model_dir):
    return load(default_model_dir)


@pytest.fixture(scope="module")
def noisy(model):
    return synthetic.make_problem(model, T, seed=1, noise_px=2.0, drop=0.15)


@pytest.fixture(scope="module")
def noisy_fit(model, noisy):
    return fit(model, noisy.keypoints, noisy.init)


_SKELETON = jax.jit(jax.vmap(smplx_jax.posed_skeleton, in_axes=(None, 0)))
_COPY_PASTE = jax.jit(jax.vmap(copy_paste, in_axes=(None, 0, 0, 0, 0, 0)))
_SMOOTH_PARAMS = jax.jit(smooth_params)
_SMOOTH_ROTVECS = jax.jit(smooth_rotvecs)


def _geodesic(ra, rb):
    """Angle of ra^T rb in radians (from its axis-angle: accurate for small angles, unlike arccos of the trace)."""
    return np.linalg.norm(np.asarray(rotations.rotmat_to_rotvec(jnp.swapaxes(ra, -1, -2) @ rb)), axis=-1)


def _clean_error(model, result, problem):
    proj = synthetic.openpose_projection(model, result.params, result.camera_scale, result.camera_trans)
    return np.linalg.norm(proj - problem.clean, axis=-1).mean(1)


# ---- copy-and-paste -------------------------------------------------------------------------------------------

def test_copy_paste_gives_each_wrist_the_hands_global_orientation(model):
    body = random_params(0, 16, max_angle=2.5)
    rng = np.random.default_rng(1)
    lw, rw = (jnp.asarray(synthetic_rotvecs(rng, 16)) for _ in range(2))
    lh, rh = jnp.asarray(rng.normal(0, 0.4, (2, 16, 15, 3)), jnp.float32)
    pasted = _COPY_PASTE(model, body, lh, lw, rh, rw)
    glob = _SKELETON(model, pasted).glob_rotmats
    assert _geodesic(glob[:, constants.LEFT_WRIST], rotations.rotvec_to_rotmat(lw)).max() <= 1e-5
    assert _geodesic(glob[:, constants.RIGHT_WRIST], rotations.rotvec_to_rotmat(rw)).max() <= 1e-5
    np.testing.assert_allclose(glob[:, constants.LEFT_WRIST], rotations.rotvec_to_rotmat(lw), atol=1e-5)
    np.testing.assert_allclose(glob[:, constants.RIGHT_WRIST], rotations.rotvec_to_rotmat(rw), atol=1e-5)
    # finger poses pasted, the rest of the body untouched
    np.testing.assert_array_equal(pasted.left_hand_pose, lh)
    np.testing.assert_array_equal(pasted.right_hand_pose, rh)
    keep = np.array([j for j in range(21) if j not in (19, 20)])
    np.testing.assert_array_equal(pasted.body_pose[:, keep], body.body_pose[:, keep])
    np.testing.assert_array_equal(pasted.betas, body.betas)


def synthetic_rotvecs(rng, n):
    axes = rng.normal(size=(n, 3))
    return (axes / np.linalg.norm(axes, axis=1, keepdims=True) * rng.uniform(0, 3.0, (n, 1))).astype(np.float32)


# ---- the 2D fit ---------------------------------------------------------------------------------------------

def test_fit_recovers_ground_truth_from_noisy_partial_keypoints(model, noisy, noisy_fit):
    r = noisy_fit
    assert np.all(np.asarray(r.status) == fitting.OK)
    err = np.asarray(r.reprojection_error_px)
    assert np.median(err) <= 2.5, np.median(err)
    assert np.all(err < np.asarray(r.initial_reprojection_error_px))
    init = fitting.FitResult(noisy.init, jnp.asarray(noisy.camera_scale), jnp.asarray(noisy.camera_trans),
                             *r[3:])  # the start, even with the true camera
    better = _clean_error(model, r, noisy) < _clean_error(model, init, noisy)
    assert better.mean() >= 0.95, better.mean()
    for leaf in jax.tree.leaves(r):
        assert np.all(np.isfinite(np.asarray(leaf)))


def test_fits_pressed_against_a_joint_limit_converge(noisy_fit):
    """At the defaults, every fit converges within the step cap, those where a finger presses against its limit
    included (29 of these 32 frames within 400 steps, 27 within 100, when the solver's model saw a limit's stiffness
    only once past it: a step from just inside landed far beyond, was refused, and the damping climbed;
    `least_squares.BEND_MARGIN`)."""
    assert np.asarray(noisy_fit.converged).all()


def test_fitted_fingers_never_bend_backwards(model, noisy):
    """From a start with the fingers bent backwards (the curl of the truth reversed), the fit bends none back by
    more than 15 degrees (the limit is soft: past 6 degrees, a residual of `prior_bend` per radian)."""
    from jaxmocap.integrate.least_squares import FINGER_BACKWARDS

    def backwards(params):
        hands = np.concatenate([params.left_hand_pose, params.right_hand_pose], 1)
        return np.degrees(np.stack([sign * hands[:, j - 25, axis] for j, axis, sign in FINGER_BACKWARDS], 1))

    left, right = np.array(noisy.init.left_hand_pose), np.array(noisy.init.right_hand_pose)
    left[:, :12, 2], right[:, :12, 2] = -left[:, :12, 2], -right[:, :12, 2]
    start = noisy.init.replace(left_hand_pose=jnp.asarray(left), right_hand_pose=jnp.asarray(right))
    assert (backwards(start) > 10).mean() > 0.5
    result = fit(model, noisy.keypoints, start)
    assert (backwards(result.params) > 15).mean() == 0, backwards(result.params).max()


def test_fit_without_noise_is_exact_to_half_a_pixel(model):
    clean = synthetic.make_problem(model, T, seed=2, noise_px=0.0, drop=0.15)
    r = fit(model, clean.keypoints, clean.init)
    assert np.median(np.asarray(r.reprojection_error_px)) <= 0.5, np.median(np.asarray(r.reprojection_error_px))


def test_a_pinhole_fit_recovers_a_near_body_and_its_place(model):
    """Keypoints of bodies 2-3 m from a pinhole camera (focal 900 px): the pinhole fit lands on them, finds where
    the body is, and its 3D pose is nearer the truth than weak perspective's (which bends the body to match)."""
    near = synthetic.make_problem(model, T, seed=4, noise_px=0.0, drop=0.15, focal_length=900.0)
    centre = np.array(synthetic.IMAGE_SIZE) / 2
    pinhole = fit(model, near.keypoints, near.init, focal_length=900.0, principal_point=centre)
    compiled = len(fitting._start_batch.programs), len(fitting._result_batch.programs)
    weak = fit(model, near.keypoints, near.init)
    # the camera is data: one compiled fit for both (`disk_jit` holds each program it ran, as the CLI's runs do)
    assert (len(fitting._start_batch.programs), len(fitting._result_batch.programs)) == compiled and all(compiled)
    assert np.all(np.asarray(pinhole.status) == fitting.OK)
    err = np.asarray(pinhole.reprojection_error_px)
    assert np.median(err) <= 0.5, np.median(err)
    def skeleton(params):  # the 22 body joints about the body origin
        return body_joints(model, params.replace(transl=0 * params.transl))[:, :22]

    truth_3d = skeleton(near.truth)
    ours, theirs = (np.median(np.linalg.norm(skeleton(r.params) - truth_3d, axis=-1)) for r in (pinhole, weak))
    assert ours < 0.7 * theirs, (ours, theirs)
    depth, truth = np.asarray(pinhole.params.transl[:, 2]), np.asarray(near.truth.transl[:, 2])
    assert np.median(np.abs(depth / truth - 1)) <= 0.1 and np.all((depth > 1.5) & (depth < 4.5))
    joints = body_joints(model, pinhole.params)[:, np.asarray(constants.OPENPOSE67_FROM_SMPLX)]
    # the stored weak perspective is the closest one: nearer than the one at the body origin's depth
    seen = near.keypoints[..., 2] > 0
    pixels = 900.0 * joints[..., :2] / joints[..., 2:] + centre

    def weak_error(scale, trans):
        return np.sum(seen[..., None] * (
            np.asarray(scale)[:, None, None] * joints[..., :2] + np.asarray(trans)[:, None] - pixels) ** 2, (1, 2))

    transl = np.asarray(pinhole.params.transl)
    at_origin = weak_error(900.0 / transl[:, 2], 900.0 * transl[:, :2] / transl[:, 2:] + centre)
    assert np.all(weak_error(pinhole.camera_scale, pinhole.camera_trans) <= at_origin * (1 + 1e-4))


def test_jit_compiles_once_per_padded_size(model, noisy, noisy_fit, monkeypatch):
    """27 frames pad to the bucket of 32; each round of steps runs only the frames still going, in their bucket.
    The 27: 22 drawn (with repeats) from the frames the module's fit finished within 40 steps and 5 from those that
    took 65 or more, so the first round (of `fitting.ROUND_STEPS` = 50) leaves a few going whatever the machine's
    rounding (measured: 22 finished in the first round, 5 in the second)."""
    functions = fitting._start_batch, fitting._advance_batch, fitting._result_batch

    def compiled():  # the programs each holds (`disk_jit`'s, as the CLI's runs keep them)
        return [len(f.programs) for f in functions]

    steps = np.asarray(noisy_fit.steps)
    short, long = np.flatnonzero(steps <= 40), np.flatnonzero(steps >= 65)
    assert len(short) and len(long) and fitting.ROUND_STEPS == 50
    pick = np.concatenate([np.resize(short, T - 10), np.resize(long, 5)])
    keypoints, sub = noisy.keypoints[pick], jax.tree.map(lambda a: a[pick], noisy.init)
    rows, finished = [], []
    monkeypatch.setattr(fitting, "_advance_batch", lambda km, problem, *rest: rows.append(len(problem.target))
                        or functions[1](km, problem, *rest))
    before = compiled()
    r = fit(model, keypoints, sub, progress=finished.append)
    assert compiled()[::2] == before[::2]  # (a later round's bucket may be new)
    going = T - 5 - np.cumsum([0] + finished[:-1])
    assert sum(finished) == T - 5 and rows == [bucket_size(int(n), fitting.BUCKETS) for n in going] and min(rows) < T
    after = compiled()
    assert all(after)
    fit(model, keypoints, sub)
    assert compiled() == after  # a second call compiles nothing
    fit(model, keypoints, sub, iterations=7)
    assert compiled() == after  # nor one with another step cap (the batches take their steps as an argument)
    assert bucket_size(T - 5, fitting.BUCKETS) == bucket_size(T, fitting.BUCKETS) == T
    # padding does not change the frames' results: those done in the first round (the same batch of 32) are the
    # same; the others ran on in other batches, whose float32 sums round in another order, to fits as good (measured
    # 22 of 27 the same, the others within 0.001 px)
    same = np.abs(np.asarray(r.params.body_pose) - np.asarray(noisy_fit.params.body_pose[pick])).max((1, 2)) < 1e-6
    gap = np.abs(np.asarray(r.reprojection_error_px) - np.asarray(noisy_fit.reprojection_error_px[pick]))
    assert same.sum() >= (T - 5) // 2 and np.asarray(r.converged).all() and gap.max() < 0.03, (same, gap)
    # the start's error is the start's, whatever batches the fit ran on in
    np.testing.assert_array_equal(r.initial_reprojection_error_px, noisy_fit.initial_reprojection_error_px[pick])


def test_vmapped_fit_equals_the_fit_of_each_frame_alone(default_model_dir, noisy):
    """vmap = loop, in float64, over 20 steps: in float32 the batched sums round in another order, and the fit's
    accept/reject decisions amplify that along weakly determined directions (frames then differ by up to ~1 px and
    land in different, about equally good minima; the batched fit's accuracy is tested above); run to convergence
    they agree to the stopping rule's tolerance (~1e-6), not to 1e-8."""
    frames = np.array([0, 7, 18])
    with jax.enable_x64(True):
        model = smplx_jax.load_model(default_model_dir / "smplx" / "SMPLX_NEUTRAL.npz", dtype=jnp.float64)
        keypoints = jnp.asarray(noisy.keypoints[frames], jnp.float64)
        init = jax.tree.map(lambda a: jnp.asarray(np.asarray(a)[frames], jnp.float64), noisy.init)
        one = functools.partial(fit_frame, model, iterations=20)
        batched = jit_fast_compile(jax.vmap(one))(keypoints, init)
        single = jit_fast_compile(one)
        for i in range(len(frames)):
            alone = single(keypoints[i], jax.tree.map(lambda a: a[i], init))
            assert int(alone.status) == fitting.OK
            for a, b in zip(jax.tree.leaves(alone), jax.tree.leaves(batched)):
                np.testing.assert_allclose(a, b[i], rtol=0, atol=1e-8)


def test_missing_people_and_non_finite_keypoints_are_masked(model, noisy, noisy_fit):
    kp = noisy.keypoints.copy()
    kp[3] = 0.0  # nobody in frame 3
    kp[4, :10] = np.nan  # broken keypoints in frame 4
    kp[5, 30] = np.inf
    r = fit(model, kp, noisy.init)
    status = np.asarray(r.status)
    assert status[3] == fitting.NO_KEYPOINTS and np.all(np.delete(status, 3) == fitting.OK)
    np.testing.assert_array_equal(r.params.body_pose[3], noisy.init.body_pose[3])  # the start, marked
    assert not np.asarray(r.valid)[3]
    for leaf in jax.tree.leaves(r):
        assert np.all(np.isfinite(np.asarray(leaf)))
    assert np.asarray(r.reprojection_error_px)[4] < 2.5 * 2


def test_non_finite_initial_parameters_are_an_error(model, noisy):
    bad = noisy.init.replace(body_pose=noisy.init.body_pose.at[2, 3, 0].set(jnp.nan))
    with pytest.raises(ValueError, match="NaN or inf"):
        fit(model, noisy.keypoints, bad)
    with pytest.raises(ValueError, match=r"\(T, 67, 3\)"):
        fit(model, noisy.keypoints[:, :25], noisy.init)


# ---- IK -----------------------------------------------------------------------------------------------------

def test_ik_recovers_joint_rotations_from_3d_joints(model):
    rng = np.random.default_rng(3)
    n = 16
    theta = synthetic.random_pose(rng, n)
    betas = np.zeros((n, model.num_betas), np.float32)
    index = [i for i in range(76) if i not in (22, 23, 24)]  # skeleton and vertex joints (not jaw, eyes)
    joints = np.asarray(jax.vmap(smplx_jax.forward_joints, in_axes=(None, 0))(
        model, fitting.params_from_full_pose(jnp.asarray(theta), jnp.asarray(betas), model.num_expression)))[:, index]
    start = theta + rng.normal(0, 0.1, theta.shape).astype(np.float32)
    free = tuple(j not in (22, 23, 24) for j in range(55))
    fitted, _, cam, ok = ik(model, index, joints, np.ones(joints.shape[:2]), start, betas, free)
    assert np.all(np.asarray(ok))
    def rot(a):
        return rotations.rotvec_to_rotmat(jnp.asarray(a))
    err, err0 = _geodesic(rot(fitted), rot(theta))[:, list(free)], _geodesic(rot(start), rot(theta))[:, list(free)]
    assert np.median(err) < 0.6 * np.median(err0), (np.median(err), np.median(err0))
    assert np.median(err[:, 0]) < 0.02  # the root is fully determined by the hips and spine
    np.testing.assert_allclose(np.asarray(cam)[:, 0], 1.0, atol=0.01)
    # 13 frames pad to the bucket 16 frames padded to (32): the solver compiled for 16 serves, with the same rows
    compiled = len(inverse_kinematics._ik_batch.programs)
    again, *_ = ik(model, index, joints[:13], np.ones((13, len(index))), start[:13], betas[:13], free)
    assert len(inverse_kinematics._ik_batch.programs) == compiled > 0
    np.testing.assert_array_equal(np.asarray(again), np.asarray(fitted)[:13])


# ---- smoothing ----------------------------------------------------------------------------------------------

def test_smoothing_rotations_near_pi_is_rotation_safe():
    # rotations within 0.05 rad of pi about x, whose axis-angles flip sign from frame to frame
    angles = np.pi - 0.02 + 0.01 * np.sin(np.arange(12))
    rotvecs = np.stack([angles, np.zeros(12), np.zeros(12)], 1) * np.where(np.arange(12) % 2, 1, -1)[:, None]
    rotvecs = jnp.asarray(rotvecs, jnp.float32)
    out = _SMOOTH_ROTVECS(rotvecs, jnp.ones(12, bool))
    assert _geodesic(rotations.rotvec_to_rotmat(out), rotations.rotvec_to_rotmat(rotvecs)).max() < 0.05
    # what averaging raw axis-angles would have done: rotations near zero, ~pi away
    naive = np.stack([np.convolve(rotvecs[:, 0], [0.1, 0.2, 0.5, 0.2, 0.1], mode="same"), np.zeros(12),
                      np.zeros(12)], 1)
    naive_err = _geodesic(rotations.rotvec_to_rotmat(jnp.asarray(naive, jnp.float32)),
                          rotations.rotvec_to_rotmat(rotvecs))
    assert naive_err[2:-2].min() > 1.5


def test_smoothing_keeps_constant_motion_and_reduces_jitter(model):
    p = random_params(4, 1, max_angle=1.0)
    const = jax.tree.map(lambda a: jnp.repeat(a, 20, 0), p)
    out = _SMOOTH_PARAMS(const, jnp.ones(20, bool))
    np.testing.assert_allclose(out.body_pose, const.body_pose, atol=2e-5)
    rng = np.random.default_rng(5)
    noisy = const.replace(body_pose=const.body_pose + jnp.asarray(rng.normal(0, 0.05, (20, 21, 3)), jnp.float32))
    valid = jnp.ones(20, bool).at[7].set(False)
    out = _SMOOTH_PARAMS(noisy, valid)
    assert float(jnp.abs(out.body_pose - const.body_pose).mean()) < 0.7 * float(jnp.abs(noisy.body_pose -
                                                                                      const.body_pose).mean())
    np.testing.assert_array_equal(out.body_pose[7], noisy.body_pose[7])  # invalid frames are left alone


# ---- motion.npz and the command line ------------------------------------------------------------------------

def test_image_size_is_inferred_from_the_keypoints():
    kp = np.zeros((2, 67, 3), np.float32)
    kp[0, 3] = (640.2, 100, 1)
    kp[1, 9] = (10, 479.0, 1)
    kp[1, 10] = (5000, 5000, 0)  # missing points do not count
    assert infer_image_size(kp) == (642, 480)


def test_fit_command_errors_are_one_line(tmp_path, capsys):
    assert main(["fit", str(tmp_path / "missing"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing" in err
    (tmp_path / "kp").mkdir()
    (tmp_path / "kp" / "a_keypoints.json").write_text("{not json")
    assert main(["fit", str(tmp_path / "kp"), "--out", str(tmp_path / "out")]) == 2
    assert "a_keypoints.json" in capsys.readouterr().err
    (tmp_path / "kp" / "a_keypoints.json").write_text('{"people": []}')
    for option, message in ((["--focal-length", "0"], "--focal-length must be positive"),
                            (["--image-size", "0", "480"], "--image-size must be positive"),
                            (["--iterations", "-1"], "--iterations must be >= 0")):
        assert main(["fit", str(tmp_path / "kp"), "--out", str(tmp_path / "out"), *option]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and message in err, err
