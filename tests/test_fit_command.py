"""``jaxmocap fit``: OpenPose JSON of a moving body fitted as one clip (`fit_folder`), from the start that the 2D
keypoints alone give (`keypoint_start.facing_pose`); the motion file it writes, as the ``smplx`` package reads it."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import smplx
import torch

import smplx_jax
from jaxmocap.cli import main
from jaxmocap.detect.openpose import json_name, write_openpose_json
from jaxmocap.integrate import synthetic
from jaxmocap.integrate.clip import points_3d
from jaxmocap.integrate.fitting import openpose_keypoint_model
from jaxmocap.integrate.keypoint_start import facing_pose
from jaxmocap.motion import motion_params, read_motion
from jaxmocap.pipeline.fit_folder import fitted_keypoints
from jaxmocap.pipeline.whole_clip import SHAPE_FRAMES, SHAPE_RUNS, shape_frames
from smplx_jax import constants
from smplx_jax.rotations import rotmat_to_rotvec, rotvec_to_rotmat
from train.metrics import pa_mpjpe

MODEL = smplx_jax.load_model(smplx_jax.default_model_path())
FOCAL, CENTRE = 1500.0, np.array([960.0, 540.0])
FRAMES = 24


def _degrees(a, b):
    """The angle between the rotations of axis-angles ``a`` and ``b`` (..., 3), degrees."""
    relative = np.swapaxes(np.asarray(rotvec_to_rotmat(jnp.asarray(a, jnp.float32))), -1, -2) @ np.asarray(
        rotvec_to_rotmat(jnp.asarray(b, jnp.float32)))
    return np.degrees(np.arccos(np.clip((np.trace(relative, axis1=-2, axis2=-1) - 1) / 2, -1.0, 1.0)))


def _orient(rotmats):
    return np.asarray(rotmat_to_rotvec(jnp.asarray(rotmats, jnp.float32)))


def _points(pose, betas, transl):
    """``(T, 67, 3)`` the keypoints in the camera frame of poses ``(T, 55, 3)``, a shape ``(T, B)``, ``transl``."""
    km = openpose_keypoint_model(MODEL)
    return np.asarray(jax.vmap(lambda p, b, t: points_3d(km, p, b, t))(
        jnp.asarray(pose, jnp.float32), jnp.asarray(np.broadcast_to(betas, (len(pose), MODEL.num_betas)),
                                                    jnp.float32), jnp.asarray(transl, jnp.float32)))


def _pixels(pose, betas, transl):
    x = _points(pose, betas, transl)
    return np.concatenate([FOCAL * x[..., :2] / x[..., 2:] + CENTRE, np.ones(x.shape[:-1] + (1,))], -1)


def _seen(view: str, frames: int = 12, noise_px: float = 0.0):
    """`synthetic.make_clip`'s body facing the camera (turning +-17 degrees), the same seen from behind (turned half
    round about its vertical), or its image turned a quarter round: its poses (the global orientation as the
    camera sees it) and its keypoints, with ``noise_px`` of noise."""
    clip = synthetic.make_clip(MODEL, frames, focal_length=FOCAL, principal_point=CENTRE)
    orient = np.asarray(rotvec_to_rotmat(jnp.asarray(clip.pose[:, 0], jnp.float32)), np.float64)
    if view == "back":
        orient = orient @ np.asarray(rotvec_to_rotmat(jnp.asarray([0.0, np.pi, 0.0])), np.float64)
    pose = clip.pose.copy()
    pose[:, 0] = _orient(orient)
    keypoints = _pixels(pose, clip.betas, clip.transl)
    if view == "rolled":  # the camera turned a quarter round about its axis
        quarter = np.asarray([[0.0, -1.0], [1.0, 0.0]])
        keypoints[..., :2] = (keypoints[..., :2] - CENTRE) @ quarter.T + CENTRE
        pose[:, 0] = _orient(np.asarray(rotvec_to_rotmat(jnp.asarray([0.0, 0.0, np.pi / 2])), np.float64) @ orient)
    keypoints[..., :2] += np.random.default_rng(0).normal(scale=noise_px, size=keypoints[..., :2].shape)
    return pose, keypoints.astype(np.float32)


@pytest.mark.parametrize("view", ["front", "back", "rolled"])
def test_the_start_faces_the_way_the_keypoints_show(view):
    """The start's global orientation within 25 degrees of the body's in every frame (it turns no further than the
    image shows: the body's own turn is the fit's to find)."""
    pose, keypoints = _seen(view)
    start = np.asarray(jax.vmap(facing_pose)(jnp.asarray(keypoints)))
    off = _degrees(start[:, 0], pose[:, 0])
    assert np.all(off < 25.0), off


def test_a_body_seen_from_behind_is_fitted_facing_away():
    """Seen from behind (1 px of noise), the clip fit from the keypoints' start ends facing as the body does in
    every frame, within 15 degrees (from the default pose, facing the camera, it would have to turn round)."""
    pose, keypoints = _seen("back", FRAMES, noise_px=1.0)
    fitted = fitted_keypoints(MODEL, keypoints, (FOCAL, CENTRE), 30.0)
    assert fitted.converged.all()
    off = _degrees(np.asarray(fitted.bodies.params.global_orient), pose[:, 0])
    assert np.all(off < 15.0), off


def test_the_shape_is_fitted_on_runs_of_a_video_and_spread_frames_of_images():
    valid = np.ones(200, bool)
    valid[:10] = False
    frames, found = shape_frames(valid, video=True)
    runs = frames.reshape(SHAPE_RUNS, -1)
    assert len(frames) == SHAPE_FRAMES and np.all(np.diff(runs, axis=1) == 1)  # consecutive frames
    assert runs[0, 0] == 10 and runs[-1, -1] == 199  # from the first valid frame to the last
    assert not found.reshape(SHAPE_RUNS, -1)[:, -1].any() and found.reshape(SHAPE_RUNS, -1)[:, :-1].all()
    frames, found = shape_frames(valid, video=False)
    assert found.all() and np.all(np.diff(frames) > 1) and frames[0] == 10 and frames[-1] == 199
    frames, found = shape_frames(np.arange(200) % 50 == 0, video=False)  # four valid frames
    assert found.sum() == 4 and set(frames) == {0, 50, 100, 150}


@pytest.fixture(scope="module")
def fitted_folder(tmp_path_factory):
    """A clip's keypoints with 1 px of noise, 15% dropped, nobody in frame 5, as OpenPose JSON; fitted from the
    keypoints alone."""
    clip = synthetic.make_clip(MODEL, FRAMES, focal_length=FOCAL, principal_point=CENTRE)
    rng = np.random.default_rng(0)
    keypoints = clip.keypoints.copy()
    keypoints[..., :2] += rng.normal(scale=1.0, size=keypoints[..., :2].shape)
    keypoints[rng.uniform(size=keypoints.shape[:2]) < 0.15] = 0.0
    folder = tmp_path_factory.mktemp("fit")
    (folder / "keypoints").mkdir()
    for i in range(FRAMES):
        write_openpose_json(folder / "keypoints" / json_name("clip", i),
                            keypoints[i:i + 1] if i != 5 else np.zeros((0, 67, 3)))
    assert main(["fit", str(folder / "keypoints"), "--out", str(folder / "first"), "--quiet", "--image-size",
                 "1920", "1080", "--focal-length", str(FOCAL), "--fps", "30"]) == 0
    return clip, folder


def test_the_fit_command_fits_the_clips_motion(fitted_folder):
    """On its keypoints, one shape, every frame facing as the body does, and its joints in 3D within centimetres of
    the body's up to a similarity (the depth and size one camera cannot tell apart)."""
    clip, folder = fitted_folder
    motion = read_motion(folder / "first" / "motion.npz")
    valid = motion["valid"]
    assert not valid[5] and valid.sum() == FRAMES - 1
    assert np.median(motion["reprojection_error_px"][valid]) < 2.0, motion["reprojection_error_px"]
    assert np.all(motion["betas"] == motion["betas"][:1])
    assert np.all(_degrees(motion["global_orient"][valid], clip.pose[valid, 0]) < 15.0)
    params = motion_params(motion)
    ours = _points(jax.vmap(smplx_jax.SMPLXParams.full_pose)(params), params.betas, params.transl)[valid, :25]
    truth = _points(clip.pose, clip.betas, clip.transl)[valid, :25]
    errors = pa_mpjpe(ours, truth, np.ones(ours.shape[:2], bool))
    assert 1000 * np.median(errors) < 40.0, 1000 * np.asarray(errors)


def test_the_fit_commands_motion_file_is_the_smplx_packages_body(fitted_folder, default_model_dir):
    """From the first fit's motion (``--init``), frames as unrelated images: the file's keys and shapes, and the
    ``smplx`` package's joints of its parameters land on its stored reprojection errors through its pinhole."""
    clip, folder = fitted_folder
    assert main(["fit", str(folder / "keypoints"), "--out", str(folder / "out"), "--quiet", "--no-smooth",
                 "--init", str(folder / "first" / "motion.npz"), "--image-size", "1920", "1080", "--focal-length",
                 str(FOCAL), "--fps", "25"]) == 0
    path = folder / "out" / "motion.npz"
    with np.load(path) as f:
        data = {k: f[k] for k in f.files}
    t = FRAMES
    shapes = dict(global_orient=(t, 3), body_pose=(t, 21, 3), left_hand_pose=(t, 15, 3), right_hand_pose=(t, 15, 3),
                  jaw_pose=(t, 3), betas=(t, 10), transl=(t, 3), camera_scale=(t,), camera_trans=(t, 2), valid=(t,),
                  keypoints_2d=(t, 67, 3), reprojection_error_px=(t,), fps=(), image_size=(2,), model_sha256=(),
                  focal_length=(), principal_point=(2,))
    assert set(data) == set(shapes)
    for k, shape in shapes.items():
        assert data[k].shape == shape, k
    assert data["valid"].dtype == bool and not data["valid"][5] and data["valid"].sum() == t - 1
    assert data["fps"] == 25 and data["model_sha256"].dtype.kind == "U" and len(str(data["model_sha256"])) == 64
    assert data["image_size"].tolist() == [1920, 1080] and data["focal_length"] == FOCAL
    body = smplx.create(str(default_model_dir), model_type="smplx", use_pca=False, flat_hand_mean=True, batch_size=t)

    def tensor(k):
        return torch.tensor(data[k]).reshape(t, -1)

    with torch.no_grad():
        joints = body(global_orient=tensor("global_orient"), body_pose=tensor("body_pose"),
                      left_hand_pose=tensor("left_hand_pose"), right_hand_pose=tensor("right_hand_pose"),
                      jaw_pose=tensor("jaw_pose"), betas=tensor("betas"), transl=tensor("transl")).joints.numpy()
    x = joints[:, list(constants.OPENPOSE67_FROM_SMPLX)]
    pixels = data["focal_length"] * x[..., :2] / x[..., 2:] + data["principal_point"]
    seen = data["keypoints_2d"][..., 2] > 0
    distance = np.where(seen, np.linalg.norm(pixels - data["keypoints_2d"][..., :2], axis=-1), 0)
    errors = distance.sum(1) / np.maximum(seen.sum(1), 1)
    valid = data["valid"]
    np.testing.assert_allclose(errors[valid], data["reprojection_error_px"][valid], atol=0.01)
    assert np.median(errors[valid]) < 2.0
