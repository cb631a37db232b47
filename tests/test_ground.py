"""The floor and the world frame (`jaxmocap.integrate.ground`): a body that stands and steps on a known floor, seen
by a tilted camera, gives that floor back, its world keys move the body onto it (as the PyTorch ``smplx`` package
computes it too), and its feet touch the floor only while they rest."""

import dataclasses

import jax
import numpy as np
import pytest
import smplx
import torch

import smplx_jax
from conftest import load
from jaxmocap.errors import InputError
from jaxmocap.integrate import ground
from jaxmocap.integrate.motion_arrays import body_joints
from jaxmocap.motion import WORLD_SHAPES, write_motion
from smplx_jax import rotations

FPS = 60.0
STANCE, STEP = 30, 12  # frames standing still at each place, then moving to the next


@pytest.fixture(scope="module")
def model(default_model_dir):
    return load(default_model_dir)


def _camera_from_world(pitch_deg: float, roll_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """(R, t) of a camera looking along the world's -z, down by ``pitch_deg``, rolled by ``roll_deg`` (x right,
    y down), the world's origin 4 m ahead."""
    pitch = np.asarray(rotations.rotvec_to_rotmat(np.array([np.pi + np.radians(pitch_deg), 0.0, 0.0])))
    roll = np.asarray(rotations.rotvec_to_rotmat(np.array([0.0, 0.0, np.radians(roll_deg)])))
    return roll @ pitch, np.array([0.1, 0.5, 4.0])


def stepping(model, rotation: np.ndarray, t: np.ndarray, seed: int = 0):
    """A body in its rest pose standing at 8 random places of the floor (y = 0 under its soles), each facing its
    own way, moving between them; seen by the camera ``(rotation, t)``: its parameters in the camera's frame and
    which frames it stands still in."""
    rng = np.random.default_rng(seed)
    places = rng.uniform([-1.0, -1.0, -np.pi], [1.0, 1.0, np.pi], (8, 3))
    path = np.concatenate([np.concatenate([np.repeat(a[None], STANCE, 0),
                                           a + np.linspace(0, 1, STEP)[:, None] * (b - a)])
                           for a, b in zip(places[:-1], places[1:])])
    still = np.tile(np.r_[np.ones(STANCE, bool), np.zeros(STEP, bool)], len(places) - 1)
    rest = smplx_jax.SMPLXParams.zeros(model.num_betas, model.num_expression)
    sole = float(np.asarray(smplx_jax.forward(model, rest).vertices)[:, 1].min())
    pelvis = np.asarray(smplx_jax.forward_joints(model, rest))[0]
    transl_world = np.stack([path[:, 0], np.full(len(path), -sole), path[:, 1]], 1)
    facing = np.asarray(rotations.rotvec_to_rotmat(np.stack([0 * path[:, 2], path[:, 2], 0 * path[:, 2]], 1)))
    params = jax.tree.map(lambda a: np.repeat(np.asarray(a)[None], len(path), 0), rest)
    params = dataclasses.replace(
        params, global_orient=np.asarray(rotations.rotmat_to_rotvec(rotation @ facing), np.float32),
        transl=((pelvis + transl_world) @ rotation.T + t - pelvis).astype(np.float32))
    return params, still


def world_keys(model, params, valid) -> dict:
    """One person's world keys, standing on the floor their motion shows."""
    people = {0: (params, valid)}
    return ground.world_arrays(model, people, 0, ground.standing(model, people, FPS, 0))[0]


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0))))


@pytest.mark.parametrize("pitch, roll", [(25.0, 8.0), (0.0, 30.0)])
def test_the_floor_and_the_world_frame_of_a_body_stepping_on_it(model, pitch, roll):
    rotation, t = _camera_from_world(pitch, roll)
    params, still = stepping(model, rotation, t)
    valid = np.ones(len(still), bool)
    world = world_keys(model, params, valid)
    assert _angle_deg(world["floor"][:3], rotation[:, 1]) < 0.1  # the world's up seen from the camera
    camera_from_world = world["camera_from_world"]
    assert np.ptp(camera_from_world, axis=0).max() == 0.0 and _angle_deg(camera_from_world[0, :3, 1],
                                                                          rotation[:, 1]) < 0.1
    moved = dataclasses.replace(params, global_orient=world["world_global_orient"], transl=world["world_transl"])
    in_world = body_joints(model, moved)
    in_camera = body_joints(model, params)
    rot, shift = camera_from_world[0, :3, :3], camera_from_world[0, :3, 3]
    assert np.abs(in_world @ rot.T + shift - in_camera).max() < 1e-3  # the same body, 1 mm
    soles = in_world[:, ground.FOOT_JOINTS, 1] - ground.sole_heights(model, np.zeros(model.num_betas))
    contact = world["contact"]
    assert contact.dtype == bool and contact.shape == (len(still), 4)
    assert np.abs(soles[contact]).max() < 0.01  # on the floor, y = 0
    assert not contact[~still].any() and contact[still].mean() > 0.5  # only while standing still
    first_pelvis = in_world[0, 0]
    assert abs(first_pelvis[0]) < 1e-3 and abs(first_pelvis[2]) < 1e-3  # the origin under the first pelvis


def test_a_bystander_seen_at_another_scale_stands_on_their_own_plane(model):
    """A second person standing still through the whole clip (more resting frames than the main person's), their
    fit 8% too far along the rays (a monocular fit's scale: their stature unknown): the scene's floor stays the
    main person's, each keeps their contacts on their own plane (parallel: one normal), and in the world the
    bystander is lowered from theirs onto the floor, their resting soles at y = 0."""
    rotation, t = _camera_from_world(25.0, 8.0)
    params, still = stepping(model, rotation, t)
    other, _ = stepping(model, rotation, t, seed=1)
    other = jax.tree.map(lambda a: np.repeat(a[:1], len(still), 0), other)  # standing at one place throughout
    pelvis = body_joints(model, other)[:, 0]
    other = dataclasses.replace(other, transl=(other.transl + 0.08 * pelvis).astype(np.float32))
    valid = np.ones(len(still), bool)
    people = {0: (params, valid), 1: (other, valid)}
    standing = ground.standing(model, people, FPS, 0)
    alone = ground.standing(model, {0: people[0]}, FPS, 0)
    assert abs(standing.floor.offset - alone.floor.offset) < 0.005 and _angle_deg(standing.floor.normal,
                                                                                  rotation[:, 1]) < 0.5
    moved_by = float(standing.floor.normal @ (0.08 * pelvis[0]))  # the bystander's soles, moved along the normal
    assert abs(standing.planes[1].offset - (standing.planes[0].offset - moved_by)) < 0.005 and abs(moved_by) > 0.05
    assert standing.contact[0][still].mean() > 0.5 and standing.contact[1].mean() > 0.9
    world = ground.world_arrays(model, people, 0, standing)[1]
    moved = dataclasses.replace(other, global_orient=world["world_global_orient"], transl=world["world_transl"])
    soles = body_joints(model, moved)[:, ground.FOOT_JOINTS, 1] - ground.sole_heights(model, np.zeros(10))
    assert np.abs(soles[world["contact"]]).max() < 0.01


def test_heels_and_toes_stand_above_the_rest_meshs_soles(model):
    """`ground.sole_heights` from the shaped template: the rest pose's mesh (`smplx_jax.forward`) gives the same."""
    betas = np.random.default_rng(0).normal(size=model.num_betas).astype(np.float32)
    rest = smplx_jax.SMPLXParams.zeros(model.num_betas, model.num_expression)
    out = smplx_jax.forward(model, dataclasses.replace(rest, betas=betas))
    expected = np.asarray(out.joints)[list(ground.FOOT_JOINTS), 1] - np.asarray(out.vertices)[:, 1].min()
    np.testing.assert_allclose(ground.sole_heights(model, betas), expected, atol=1e-6)


def test_the_floor_holds_under_depth_noise(model):
    """Each frame's depth off by 3 cm (a monocular fit's noise), its x and y by 5 mm: the floor within 1 degree."""
    rotation, t = _camera_from_world(25.0, 8.0)
    params, still = stepping(model, rotation, t, seed=1)
    noise = np.random.default_rng(2).normal(size=params.transl.shape) * np.array([0.005, 0.005, 0.03])
    noisy = dataclasses.replace(params, transl=(params.transl + noise).astype(np.float32))
    world = world_keys(model, noisy, np.ones(len(still), bool))
    assert _angle_deg(world["floor"][:3], rotation[:, 1]) < 1.0


def test_smplx_gives_the_world_body_from_the_world_keys(model, default_model_dir):
    rotation, t = _camera_from_world(25.0, 8.0)
    params, still = stepping(model, rotation, t)
    world = world_keys(model, params, np.ones(len(still), bool))
    frames = slice(0, len(still), 10)
    peer = smplx.create(str(default_model_dir), model_type="smplx", num_betas=10, num_expression_coeffs=10,
                        use_pca=False, flat_hand_mean=True, batch_size=len(still[frames]))
    with torch.no_grad():
        joints = peer(global_orient=torch.tensor(world["world_global_orient"][frames]),
                      transl=torch.tensor(world["world_transl"][frames])).joints.numpy()
    rot, shift = world["camera_from_world"][0, :3, :3], world["camera_from_world"][0, :3, 3]
    camera = body_joints(model, jax.tree.map(lambda a: a[frames], params))
    assert np.abs((camera - shift) @ rot - joints).max() < 1e-3


def test_a_motion_has_every_world_key_or_none(tmp_path):
    frames = 3
    motion = {"global_orient": np.zeros((frames, 3)), "body_pose": np.zeros((frames, 21, 3)),
              "left_hand_pose": np.zeros((frames, 15, 3)), "right_hand_pose": np.zeros((frames, 15, 3)),
              "jaw_pose": np.zeros((frames, 3)), "betas": np.zeros((frames, 10)), "transl": np.zeros((frames, 3)),
              "camera_scale": np.ones(frames), "camera_trans": np.zeros((frames, 2)), "valid": np.ones(frames, bool),
              "keypoints_2d": np.zeros((frames, 67, 3)), "reprojection_error_px": np.zeros(frames),
              "fps": np.asarray(30.0), "image_size": np.asarray([64, 48]), "model_sha256": np.asarray("0" * 64)}
    world = {"world_global_orient": np.zeros((frames, 3)), "world_transl": np.zeros((frames, 3)),
             "camera_from_world": np.repeat(np.eye(4)[None], frames, 0), "contact": np.zeros((frames, 4), bool),
             "floor": np.array([0.0, -1.0, 0.0, 1.5])}
    assert set(world) == set(WORLD_SHAPES)
    write_motion(tmp_path / "motion.npz", motion | world)
    with pytest.raises(InputError, match="without 'world_transl'"):
        write_motion(tmp_path / "motion.npz", motion | {k: v for k, v in world.items() if k != "world_transl"})
    with pytest.raises(InputError, match="'contact' has shape"):
        write_motion(tmp_path / "motion.npz", motion | world | {"contact": np.zeros((frames, 2), bool)})


def test_a_turning_camera_sees_the_same_world(model):
    """The stepping body seen by a camera that pans and tilts about its centre (up to 20 degrees, each frame's turn
    given, `ground.standing`'s ``scene_from_camera``): the same floor, contacts and world body as from the camera
    held still; each frame's ``camera_from_world`` turned with it."""
    rotation, t = _camera_from_world(25.0, 8.0)
    params, still = stepping(model, rotation, t)
    frames = len(still)
    turns = np.radians(np.stack([10 * np.sin(np.linspace(0, 3, frames)), np.linspace(0, 20, frames),
                                 np.zeros(frames)], 1))
    scene_from_camera = np.asarray(rotations.rotvec_to_rotmat(turns), np.float64)
    pelvis = np.asarray(smplx_jax.forward_joints(model, smplx_jax.SMPLXParams.zeros(model.num_betas,
                                                                                     model.num_expression)))[0]
    root = np.asarray(rotations.rotvec_to_rotmat(params.global_orient), np.float64)
    seen = dataclasses.replace(
        params, global_orient=np.asarray(rotations.rotmat_to_rotvec(np.swapaxes(scene_from_camera, 1, 2) @ root),
                                         np.float32),
        transl=(np.einsum("tji,tj->ti", scene_from_camera, params.transl + pelvis) - pelvis).astype(np.float32))
    valid = np.ones(frames, bool)
    held = world_keys(model, params, valid)
    people = {0: (seen, valid)}
    turning = ground.world_arrays(model, people, 0, ground.standing(model, people, FPS, 0, scene_from_camera=turns),
                                  turns)[0]
    np.testing.assert_allclose(turning["floor"], held["floor"], atol=1e-4)
    assert np.mean(turning["contact"] == held["contact"]) > 0.99
    def in_world(params, world):
        return body_joints(model, dataclasses.replace(params, global_orient=world["world_global_orient"],
                                                      transl=world["world_transl"]))

    np.testing.assert_allclose(in_world(seen, turning), in_world(params, held), atol=1e-3)
    np.testing.assert_allclose(turning["camera_from_world"][:, :3, :3],
                               np.swapaxes(scene_from_camera, 1, 2) @ held["camera_from_world"][:, :3, :3], atol=1e-5)
