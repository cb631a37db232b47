"""`jaxmocap.integrate.fit_clip`: one person's clip as one least-squares problem, on synthetic clips made by the
body model (their keypoints, and their bones' directions as the 3D landmarks give them)."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smplx_jax
from jaxmocap.integrate import clip, synthetic
from jaxmocap.integrate.clip_solver import Step, moved
from jaxmocap.integrate.fitting import openpose_keypoint_model
from jaxmocap.integrate.keypoints import params_of
from jaxmocap.integrate.levenberg_marquardt import cost_of
from smplx_jax.rotations import rotmat_to_rotvec, rotvec_to_rotmat

FOCAL, CENTRE, FPS = 1500.0, np.array([960.0, 540.0]), 30.0
MODEL = smplx_jax.load_model(smplx_jax.default_model_path())


def synthetic_clip(frames: int, seed: int = 0) -> synthetic.SyntheticClip:
    """`synthetic.make_clip` through this module's camera: poses, shape, translations, keypoints, directions."""
    return synthetic.make_clip(MODEL, frames, seed, FOCAL, CENTRE, FPS)


def start_of(pose, transl, noise: float, seed: int = 1):
    rng = np.random.default_rng(seed)
    start = pose + rng.normal(scale=noise, size=pose.shape)
    start[:, 22:25] = 0.0
    params = jax.vmap(params_of, in_axes=(0, None, None))(jnp.asarray(start, jnp.float32),
                                                          jnp.zeros(MODEL.num_betas), MODEL.num_expression)
    return params.replace(transl=jnp.asarray(transl + rng.normal(scale=noise / 2, size=transl.shape), jnp.float32))


def keypoints_3d(params) -> np.ndarray:
    """``(T, 67, 3)`` the OpenPose keypoints in the camera frame: what the observations see (the spine's joints,
    which none does, are the priors' to place)."""
    km = openpose_keypoint_model(MODEL)
    return np.asarray(jax.vmap(lambda p: clip.points_3d(km, p.full_pose(), p.betas, p.transl))(params))


def fitted(keypoints, start, directions, fit_betas=True):
    frames = len(keypoints)
    return jax.jit(lambda k, s, d: clip.fit_clip(
        MODEL, k, s, focal_length=FOCAL, principal_point=CENTRE, fps=FPS,
        keypoint_sigma_px=np.full((frames, 67), 0.5), directions=d, direction_weight=np.ones(d.shape[:2]),
        fit_betas=fit_betas))(keypoints, start, directions)


def test_a_clip_fitted_from_a_rough_start_comes_back():
    """Keypoints and bone directions of a moving body of known shape, from a start 1 degree off in every joint
    and 1 cm off: the fit ends on the keypoints (its priors pull by less than a pixel) and its keypoints in 3D
    within millimetres of the body's. (From 3 degrees off, one frame's foot ends turned the other way in depth:
    a local minimum, which the start chosen over time is for.)"""
    pose, betas, transl, keypoints, directions = synthetic_clip(12)
    start = start_of(pose, transl, 0.02)
    result = fitted(keypoints, start.replace(betas=jnp.broadcast_to(jnp.asarray(betas, jnp.float32), (12, 10))),
                    directions, fit_betas=False)
    assert float(np.max(result.reprojection_error_px)) < 1.0, result.reprojection_error_px
    truth = keypoints_3d(params_of_clip(pose, betas, transl))
    error_mm, before_mm = (1000 * np.linalg.norm(keypoints_3d(p) - truth, axis=-1) for p in (result.params, start))
    # in depth, which one image hardly sees, the priors pull by centimetres (20 mm at most here, 5 mm median)
    assert error_mm.max() < 30.0 and np.median(error_mm) < 10.0, (error_mm.max(), np.median(error_mm))
    assert np.median(before_mm) > 2 * np.median(error_mm), np.median(before_mm)


def test_the_clip_has_one_shape():
    """With the shape free, one ``betas`` in every frame; the image cannot tell a larger body farther away, so the
    keypoints are right up to one scale over the clip."""
    pose, betas, transl, keypoints, directions = synthetic_clip(12)
    result = fitted(keypoints, start_of(pose, transl, 0.02), directions)
    assert np.all(np.asarray(result.params.betas) == np.asarray(result.params.betas[:1]))
    assert float(np.max(result.reprojection_error_px)) < 1.0, result.reprojection_error_px
    ours = keypoints_3d(result.params).reshape(-1, 3)
    truth = keypoints_3d(params_of_clip(pose, betas, transl)).reshape(-1, 3)
    scale = np.sum(ours * truth) / np.sum(ours * ours)  # about the camera: depth and size go together
    error_mm = 1000 * np.linalg.norm(scale * ours - truth, axis=-1)
    # the shape prior keeps the body's proportions nearer the mean than this body's (0.3 standard deviations)
    assert np.median(error_mm) < 15.0, np.median(error_mm)


def _turned(rotvecs, rotations):
    """Axis-angles ``(..., 3)`` turned by the rotations ``(..., 3, 3)`` (on the right)."""
    return np.asarray(rotmat_to_rotvec(jnp.asarray(
        np.asarray(rotvec_to_rotmat(jnp.asarray(rotvecs, jnp.float32)), np.float64) @ rotations, jnp.float32)))


def _degrees_between(a, b):
    relative = np.swapaxes(np.asarray(rotvec_to_rotmat(jnp.asarray(a, jnp.float32))), -1, -2) @ np.asarray(
        rotvec_to_rotmat(jnp.asarray(b, jnp.float32)))
    return np.degrees(np.arccos(np.clip((np.trace(relative, axis1=-2, axis2=-1) - 1) / 2, -1.0, 1.0)))


def test_a_twist_handed_between_the_elbow_and_the_wrist_in_one_frame_is_taken_back():
    """One frame's start with 60 degrees of twist moved from the left wrist to the elbow, about the forearm (the
    same keypoints, within 0.05 mm: the image and the 3D landmarks are blind to it; the rest prior too, nearly):
    the joints' angular accelerations take it back to within 20 degrees (60 without them)."""
    pose, betas, transl, keypoints, directions = synthetic_clip(12)
    rest = np.asarray(MODEL.joint_template, np.float64)
    axis = (rest[20] - rest[18]) / np.linalg.norm(rest[20] - rest[18])
    turn = np.asarray(rotvec_to_rotmat(jnp.asarray(np.radians(60.0) * axis, jnp.float32)), np.float64)
    start = pose.copy()
    start[6, 18] = _turned(pose[6, 18], turn)
    start[6, 20] = _turned(np.zeros(3), turn.T @ np.asarray(rotvec_to_rotmat(jnp.asarray(pose[6, 20], jnp.float32))))
    result = fitted(keypoints, params_of_clip(start, betas, transl), directions, fit_betas=False)
    fitted_pose = np.asarray(jax.vmap(smplx_jax.SMPLXParams.full_pose)(result.params))
    off = _degrees_between(fitted_pose[6, [18, 20]], pose[6, [18, 20]])
    assert np.all(off < 20.0), off


def test_reweighted_steps_end_on_the_robust_costs_optimum():
    """Keypoints with noise at Cauchy's knee (1 px each way at 0.5 px) and a few gross outliers (40 px): the fit
    steps by errors weighed at each step's start (iteratively reweighted), which must end where the robust cost's
    own gradient vanishes: its Newton decrement there (the preconditioner's blocks for the Gauss-Newton matrix, as
    the solver's stopping rule has it) below the rule's tolerance, from thousands of times that at the start."""
    frames = 12
    pose, betas, transl, keypoints, directions = synthetic_clip(frames)
    rng = np.random.default_rng(2)
    noisy = keypoints.copy()
    noisy[..., :2] += rng.normal(scale=1.0, size=noisy[..., :2].shape)
    noisy[rng.integers(0, frames, 6), rng.integers(0, 25, 6), :2] += 40.0
    start = start_of(pose, transl, 0.02).replace(
        betas=jnp.broadcast_to(jnp.asarray(betas, jnp.float32), (frames, 10)))
    result = fitted(noisy, start, directions, fit_betas=False)
    assert bool(result.converged), int(result.steps)
    config = clip.ClipConfig()
    arguments = dict(focal_length=FOCAL, principal_point=CENTRE, fps=FPS, keypoint_sigma_px=np.full((frames, 67), 0.5),
                     directions=directions, direction_weight=np.ones(directions.shape[:2]), fit_betas=False)
    _, data = clip.clip_problem(MODEL, noisy, start, **arguments)

    def decrement(params):
        y = clip.ClipUnknowns(jax.vmap(smplx_jax.SMPLXParams.full_pose)(params)[:, list(clip.SOLVED_JOINTS)],
                              params.transl, params.betas[0])
        zero = Step(jnp.zeros_like(y.pose_rotvecs), jnp.zeros_like(y.transl), jnp.zeros_like(y.betas))
        gradient = jax.grad(lambda s: cost_of(clip.residuals(moved(y, s, False), data, config)))(zero)
        blocks = clip.preconditioner(y, data, config)  # damped as the solver's first step is
        inverse = blocks.damped_inverse(jax.tree.map(lambda d: 1e-2 * d, blocks.diagonal())._replace(
            betas=jnp.ones_like(zero.betas)))
        return 0.5 * float(sum(jnp.sum(a * b) for a, b in zip(gradient._replace(betas=zero.betas),
                                                              inverse(gradient._replace(betas=zero.betas)))))

    tolerance = config.tolerance_per_frame * frames
    at_start, at_end = decrement(start), decrement(result.params)
    assert at_end < tolerance < at_start / 1000, (at_start, at_end)


def test_feet_carrying_weight_stay_put_on_the_floor():
    """A body standing on both feet (its legs and root still, its arms and back moving), seen with 2 px of noise and
    3D landmarks 1 cm off, fitted from a start 5 cm off in depth with its floor and contacts known (`ClipGround`)
    and without: with them its heels and toes stay put (under a millimetre a frame, several without) on the floor
    (within 5 mm) and its depth is nearer the truth. The same compiled fit serves both (the ground's arrays)."""
    frames = 24
    pose, betas, transl, _, _ = synthetic_clip(frames)
    pose[:, [0, 1, 2, 4, 5, 7, 8, 10, 11]] = pose[:1, [0, 1, 2, 4, 5, 7, 8, 10, 11]]
    transl[:] = transl[:1]
    truth = keypoints_3d(params_of_clip(pose, betas, transl))
    rng = np.random.default_rng(3)
    pixels = FOCAL * truth[..., :2] / truth[..., 2:] + CENTRE + rng.normal(scale=2.0, size=(frames, 67, 2))
    near, far = (np.asarray(side) for side in zip(*clip.BONES))
    bones = truth[:, far] - truth[:, near] + rng.normal(scale=0.01, size=(frames, len(near), 3))
    feet = truth[:, clip.FOOT_KEYPOINTS]
    up = np.asarray(rotvec_to_rotmat(jnp.asarray(pose[0, 0], jnp.float32)), np.float64)[:, 1]  # the body's up
    offset = -float(np.min(feet[0] @ up))
    start = start_of(pose, transl, 0.02).replace(betas=jnp.broadcast_to(jnp.asarray(betas, jnp.float32), (frames, 10)))
    start = start.replace(transl=start.transl + jnp.asarray(rng.normal(scale=0.05, size=(frames, 1)) * [0.0, 0.0, 1.0],
                                                            jnp.float32))
    fit = jax.jit(lambda ground: clip.fit_clip(
        MODEL, np.concatenate([pixels, np.ones((frames, 67, 1))], -1), start, focal_length=FOCAL,
        principal_point=CENTRE, fps=FPS, keypoint_sigma_px=np.full((frames, 67), 2.0),
        directions=bones / np.linalg.norm(bones, axis=-1, keepdims=True), direction_weight=np.ones(bones.shape[:2]),
        fit_betas=False, ground=ground))
    results = {}
    for known in (0.0, 1.0):
        ground = clip.ClipGround(np.append(up, offset).astype(np.float32), (feet[0] @ up + offset).astype(np.float32),
                                 np.ones((frames, 4), np.float32), np.float32(known))
        result = fit(ground)
        x = keypoints_3d(result.params)[:, clip.FOOT_KEYPOINTS]
        results[known] = (1000 * np.linalg.norm(np.diff(x, axis=0), axis=-1).mean(),
                          1000 * np.abs(x @ up + offset - ground.above_sole).max(),
                          1000 * np.sqrt(np.mean((np.asarray(result.params.transl)[:, 2] - transl[:, 2]) ** 2)))
        assert bool(result.converged)
    (free_mm, _, free_depth_mm), (still_mm, height_mm, depth_mm) = results[0.0], results[1.0]
    assert still_mm < 1.0 < 3.0 < free_mm and height_mm < 5.0, results
    assert depth_mm < 0.8 * free_depth_mm, results


def test_a_handheld_cameras_turns_leave_the_feet_planted_in_the_scene():
    """The standing body of `test_feet_carrying_weight_stay_put_on_the_floor` seen by a handheld camera turning by
    half a degree a frame (a random walk about its centre, some 13 px a frame here), its floor and contacts known in
    the scene: given the camera's turns (``scene_from_camera``) the fit's heels and toes stay put in the scene and
    its keypoints are where the body is; taken for a still camera, the feet planted in the camera's frame fight
    every frame's image."""
    frames = 24
    pose, betas, transl, _, _ = synthetic_clip(frames)
    pose[:, [0, 1, 2, 4, 5, 7, 8, 10, 11]] = pose[:1, [0, 1, 2, 4, 5, 7, 8, 10, 11]]
    transl[:] = transl[:1]
    truth = keypoints_3d(params_of_clip(pose, betas, transl))  # the scene's frame
    rng = np.random.default_rng(4)
    turns = np.cumsum(rng.normal(scale=np.radians(0.5), size=(frames, 3)), 0)
    scene_from_camera = np.asarray(rotvec_to_rotmat(jnp.asarray(turns, jnp.float32)), np.float64)
    camera = np.einsum("tji,tkj->tki", scene_from_camera, truth)
    pixels = FOCAL * camera[..., :2] / camera[..., 2:] + CENTRE + rng.normal(scale=2.0, size=(frames, 67, 2))
    near, far = (np.asarray(side) for side in zip(*clip.BONES))
    bones = camera[:, far] - camera[:, near]
    up = np.asarray(rotvec_to_rotmat(jnp.asarray(pose[0, 0], jnp.float32)), np.float64)[:, 1]
    offset = -float(np.min(truth[0, clip.FOOT_KEYPOINTS] @ up))
    ground = clip.ClipGround(np.append(up, offset).astype(np.float32),
                             (truth[0, clip.FOOT_KEYPOINTS] @ up + offset).astype(np.float32),
                             np.ones((frames, 4), np.float32), np.float32(1.0))
    start = start_of(pose, transl, 0.02).replace(betas=jnp.broadcast_to(jnp.asarray(betas, jnp.float32), (frames, 10)))
    rest = smplx_jax.SMPLXParams.zeros(MODEL.num_betas, MODEL.num_expression)
    pelvis = np.asarray(smplx_jax.forward_joints(MODEL, rest.replace(betas=jnp.asarray(betas, jnp.float32))))[0]
    root = np.asarray(rotvec_to_rotmat(start.global_orient), np.float64)  # the start in each frame's camera's axes
    start = start.replace(
        global_orient=rotmat_to_rotvec(jnp.asarray(np.swapaxes(scene_from_camera, 1, 2) @ root, jnp.float32)),
        transl=jnp.asarray(np.einsum("tji,tj->ti", scene_from_camera, np.asarray(start.transl) + pelvis) - pelvis,
                           jnp.float32))
    fit = jax.jit(lambda turning: clip.fit_clip(
        MODEL, np.concatenate([pixels, np.ones((frames, 67, 1))], -1), start, focal_length=FOCAL,
        principal_point=CENTRE, fps=FPS, keypoint_sigma_px=np.full((frames, 67), 2.0),
        directions=bones / np.linalg.norm(bones, axis=-1, keepdims=True), direction_weight=np.ones(bones.shape[:2]),
        fit_betas=False, ground=ground, scene_from_camera=turning))
    results = {}
    for given in (True, False):
        result = fit(turns.astype(np.float32) if given else np.zeros((frames, 3), np.float32))
        x = np.einsum("tij,tkj->tki", scene_from_camera, keypoints_3d(result.params))
        results[given] = (1000 * np.linalg.norm(np.diff(x[:, clip.FOOT_KEYPOINTS], axis=0), axis=-1).mean(),
                          1000 * np.median(np.linalg.norm(x - truth, axis=-1)),
                          float(np.median(result.reprojection_error_px)))
    (still_mm, error_mm, pixels_off), (held_mm, held_error_mm, held_pixels_off) = results[True], results[False]
    assert still_mm < 1.0 and error_mm < 30.0 and pixels_off < 3.0, results  # (depth: the priors', centimetres)
    assert held_mm > 10.0 and held_error_mm > 3 * error_mm and held_pixels_off > 2 * pixels_off, results


def params_of_clip(pose, betas, transl):
    return jax.vmap(params_of, in_axes=(0, None, None))(
        jnp.asarray(pose, jnp.float32), jnp.asarray(betas, jnp.float32), MODEL.num_expression).replace(
        transl=jnp.asarray(transl, jnp.float32))


@pytest.mark.parametrize("frames", [1, 2])
def test_clips_too_short_for_an_acceleration_fit_each_frame(frames):
    pose, betas, transl, keypoints, directions = synthetic_clip(frames)
    result = clip.fit_clip(MODEL, keypoints, start_of(pose, transl, 0.05), focal_length=FOCAL,
                           principal_point=CENTRE, fps=FPS, keypoint_sigma_px=np.full((frames, 67), 2.0),
                           directions=directions, direction_weight=np.ones(directions.shape[:2]))
    assert float(np.max(result.reprojection_error_px)) < 1.0


def test_gradients_through_the_clip_fit_match_finite_differences(x64, default_model_dir):
    """Float64, three frames with their keypoints a pixel off: the derivative of a fitted keypoint in 3D (the right
    wrist of the middle frame, along a direction) with respect to the keypoints (another frame's included: the
    motion couples them) and a bone's observed direction, by implicit differentiation of the converged fit,
    against central differences of fits converged tightly (at the default tolerance the differences of two fits
    a fraction of a pixel apart are off by some percent); an unseen keypoint has none."""
    from fit64 import load64

    model = load64(default_model_dir)
    pose, betas, transl, keypoints, directions = synthetic_clip(3)
    rng = np.random.default_rng(5)
    keypoints = keypoints + np.concatenate([rng.normal(scale=1.0, size=keypoints[..., :2].shape),
                                            np.zeros(keypoints[..., 2:].shape)], -1)
    keypoints[1, 30, 2] = 0.0  # unseen
    start = jax.tree.map(lambda a: jnp.asarray(a, jnp.float64), start_of(pose, transl, 0.02))
    km = openpose_keypoint_model(model)
    along = jnp.asarray([0.3, -0.8, 0.5])

    @jax.jit
    @functools.partial(jax.value_and_grad, argnums=(0, 1), has_aux=True)
    def wrist(kp, d):
        result = clip.fit_clip(model, kp, start, focal_length=FOCAL, principal_point=CENTRE, fps=FPS,
                               keypoint_sigma_px=jnp.full((3, 67), 2.0), directions=d,
                               direction_weight=jnp.ones(d.shape[:2]),
                               config=clip.ClipConfig(iterations=500, cg_iterations=200, tolerance_per_frame=1e-14))
        p = jax.tree.map(lambda a: a[1], result.params)
        return clip.points_3d(km, p.full_pose(), p.betas, p.transl)[4] @ along, result.converged

    args = (jnp.asarray(keypoints), jnp.asarray(directions))
    (_, converged), grads = wrist(*args)
    assert bool(converged)
    for arg, where, h in ((0, (1, 4, 0), 0.2), (0, (0, 4, 1), 0.2), (1, (1, 3, 2), 1e-3)):
        def value(delta, arg=arg, where=where):
            moved = list(args)
            moved[arg] = args[arg].at[where].add(delta)
            return float(wrist(*moved)[0][0])

        numeric = (value(h) - value(-h)) / (2 * h)
        analytic = float(grads[arg][where])
        assert abs(analytic - numeric) <= 2e-2 * abs(numeric) and abs(numeric) > 1e-7, (arg, where, analytic, numeric)
    assert np.all(np.asarray(grads[0][1, 30, :2]) == 0.0)
