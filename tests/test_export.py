"""BVH and glTF exports: they parse, have the motion's frames, and reproduce the model's skeleton and mesh."""

import importlib
import json
import shutil

import jax
import numpy as np
import pytest

import smplx_jax
from conftest import load
from gltf_util import accessor, read_glb, sampled, skinned_vertices
from jaxmocap.export import animation, global_transforms, write_bvh, write_gltf
from jaxmocap.export.animation import CAMERA_TO_WORLD
from jaxmocap.motion import write_motion
from jaxmocap.result_files import file_sha256
from params_util import random_params
from smplx_jax.rotations import rotvec_to_rotmat

T, FPS, SIZE, FOCAL = 12, 25.0, (1000.0, 800.0), 1200.0
FORWARD = jax.jit(jax.vmap(smplx_jax.forward, in_axes=(None, 0)))


@pytest.fixture(scope="module")
def case(default_model_dir):
    """A motion of T frames (frame 3 invalid) and the parameters it came from."""
    model = load(default_model_dir)
    params = random_params(seed=40, batch=T, max_angle=0.8)
    flip = rotvec_to_rotmat(np.array([np.pi, 0.0, 0.0]))  # image frame: y down
    global_orient = np.asarray(smplx_jax.rotations.rotmat_to_rotvec(flip @ rotvec_to_rotmat(params.global_orient)))
    betas = np.repeat(np.asarray(params.betas[:1]), T, axis=0)
    params = params.replace(global_orient=global_orient, betas=betas, expression=np.zeros((T, 10), np.float32),
                            transl=np.zeros((T, 3), np.float32), leye_pose=np.zeros((T, 3), np.float32),
                            reye_pose=np.zeros((T, 3), np.float32))
    rng = np.random.default_rng(41)
    motion = {k: np.asarray(getattr(params, k)) for k in
              ("global_orient", "body_pose", "left_hand_pose", "right_hand_pose", "jaw_pose", "betas", "transl")}
    motion |= {"camera_scale": rng.uniform(250, 350, T), "camera_trans": rng.uniform(300, 600, (T, 2)),
               "valid": np.arange(T) != 3, "fps": np.array(FPS), "image_size": np.array(SIZE),
               "keypoints_2d": np.zeros((T, 67, 3)), "reprojection_error_px": np.zeros(T),
               "model_sha256": np.array(file_sha256(smplx_jax.default_model_path()))}
    return model, params, motion


def _expected_world(points_camera_model, motion, frame):
    """Where the motion puts model-frame points in the world, by the exporter's camera convention."""
    s, t = motion["camera_scale"][frame], motion["camera_trans"][frame]
    origin = np.concatenate([(t - np.array(SIZE) / 2) / s, [FOCAL / s]])
    return (points_camera_model + origin) @ CAMERA_TO_WORLD.T


def test_animation_matches_the_posed_skeleton(case):
    model, params, motion = case
    anim = animation(model, motion, focal_px=FOCAL)
    _, positions = global_transforms(anim)
    skeleton = jax.vmap(smplx_jax.posed_skeleton, in_axes=(None, 0))(model, params)
    for frame in (0, 5, T - 1):
        expected = _expected_world(np.asarray(skeleton.joints[frame]), motion, frame)
        np.testing.assert_allclose(positions[frame], expected, atol=1e-5)
    np.testing.assert_array_equal(anim.local_rotmats[3], anim.local_rotmats[2])  # invalid frame holds
    assert not np.allclose(positions[4], positions[2])


def test_the_world_frame_animation_is_the_body_in_the_world(case):
    """A motion with world keys is exported as SMPL-X puts its body in the world frame (y up, the floor y = 0), seen
    from a camera that turns from frame to frame; ``frame="camera"`` keeps the camera's frame turned y up, as a
    motion without them."""
    from jaxmocap.integrate.ground import world_pose

    model, params, motion = case
    pinhole = motion | {"focal_length": np.asarray(FOCAL), "principal_point": np.asarray(SIZE) / 2,
                        "transl": np.tile([0.2, -0.1, 3.0], (T, 1))}
    camera_from_world = np.repeat(np.eye(4)[None], T, 0)
    turning = np.array([0.0, 0.05, 0.01]) * np.arange(T)[:, None]  # a camera panning and rolling
    camera_from_world[:, :3, :3] = np.asarray(rotvec_to_rotmat(np.array([np.pi + 0.4, 0.2, 0.1]) + turning))
    camera_from_world[:, :3, 3] = [0.1, 1.2, 4.0]
    camera = jax.vmap(smplx_jax.posed_skeleton, in_axes=(None, 0))(model, params.replace(
        transl=pinhole["transl"].astype(np.float32)))
    orient, transl = world_pose(pinhole["global_orient"], pinhole["transl"], np.asarray(camera.joints[:, 0]),
                                camera_from_world)
    world = pinhole | {"world_global_orient": orient, "world_transl": transl, "camera_from_world": camera_from_world,
                       "floor": np.zeros(4), "contact": np.zeros((T, 4), bool)}
    _, positions = global_transforms(animation(model, world))
    for frame in (0, 5, T - 1):
        rotation, t = camera_from_world[frame, :3, :3], camera_from_world[frame, :3, 3]
        np.testing.assert_allclose(positions[frame], (np.asarray(camera.joints[frame]) - t) @ rotation, atol=1e-5)
    _, in_camera = global_transforms(animation(model, world, frame="camera"))
    _, as_before = global_transforms(animation(model, pinhole))
    np.testing.assert_allclose(in_camera, as_before, atol=1e-9)
    np.testing.assert_allclose(in_camera[0], np.asarray(camera.joints[0]) @ CAMERA_TO_WORLD.T, atol=1e-5)


def _parse_bvh(text, end_sites=None):
    """Joint names, parents, offsets, frame time and frames; the End Sites' offsets go into ``end_sites``
    (a dict by joint index), when given."""
    lines = iter(text.splitlines())
    names, parents, offsets, stack = [], [], [], []
    for line in lines:
        words = line.split()
        if words[0] in ("ROOT", "JOINT"):
            names.append(words[1])
            parents.append(stack[-1] if stack else -1)
        elif words[0] == "End":
            _, offset, _ = next(lines), next(lines), next(lines)  # { OFFSET }
            if end_sites is not None:
                end_sites[stack[-1]] = [float(w) for w in offset.split()[1:]]
        elif words[0] == "OFFSET":
            offsets.append([float(w) for w in words[1:]])
        elif words[0] == "{":
            stack.append(len(names) - 1)
        elif words[0] == "}":
            stack.pop()
        elif words[0] == "MOTION":
            break
    frames = int(next(lines).split()[1])
    frame_time = float(next(lines).split()[2])
    values = np.array([[float(w) for w in next(lines).split()] for _ in range(frames)])
    return names, parents, np.array(offsets), frame_time, values


def _zyx(deg):
    z, y, x = np.radians(deg)
    rz = np.array([[np.cos(z), -np.sin(z), 0], [np.sin(z), np.cos(z), 0], [0, 0, 1]])
    ry = np.array([[np.cos(y), 0, np.sin(y)], [0, 1, 0], [-np.sin(y), 0, np.cos(y)]])
    rx = np.array([[1, 0, 0], [0, np.cos(x), -np.sin(x)], [0, np.sin(x), np.cos(x)]])
    return rz @ ry @ rx


def test_bvh_parses_and_reproduces_the_skeleton(case, tmp_path):
    model, _, motion = case
    anim = animation(model, motion, focal_px=FOCAL)
    path = write_bvh(tmp_path / "motion.bvh", anim)
    names, parents, offsets, frame_time, values = _parse_bvh(path.read_text())
    assert len(names) == 55 and values.shape == (T, 6 + 3 * 54) and frame_time == pytest.approx(1 / FPS)
    _, expected = global_transforms(anim)
    for frame in (0, 7):
        rot, pos = [None] * 55, [None] * 55
        for k, p in enumerate(parents):
            local = _zyx(values[frame, 3 + 3 * k: 6 + 3 * k])
            if p < 0:
                rot[k], pos[k] = local, values[frame, :3]
            else:
                rot[k], pos[k] = rot[p] @ local, pos[p] + rot[p] @ offsets[k]
        order = [anim.names.index(n) for n in names]
        np.testing.assert_allclose(np.array(pos), expected[frame][order], atol=1e-4)


def test_bvh_has_no_zero_length_bone(case, tmp_path):
    """Every bone ends where Blender's importer ends it (its End Site; its one child; the mean of its children)
    at least 5 mm from its head (Blender calls 1 mm and less "zero length"), and the End Sites reach the tips
    of toes, fingers, lower lip and eyes of the motion's shape."""
    model, _, motion = case
    anim = animation(model, motion, focal_px=FOCAL)
    ends = {}
    names, parents, offsets, _, _ = _parse_bvh(write_bvh(tmp_path / "motion.bvh", anim).read_text(), ends)
    children = [[c for c, p in enumerate(parents) if p == j] for j in range(len(names))]
    assert sorted(j for j in range(len(names)) if not children[j]) == sorted(ends)  # every leaf has an End Site
    lengths = {names[j]: np.linalg.norm(ends[j] if j in ends else offsets[children[j]].mean(axis=0))
               for j in range(len(names))}
    short = {name: length for name, length in lengths.items() if length < 0.005}
    assert not short, short
    assert len(ends) == 15  # feet, jaw, eyes, 10 finger tips

    rest = np.asarray(smplx_jax.forward_joints(model, smplx_jax.SMPLXParams.zeros().replace(
        betas=np.asarray(anim.betas, np.float32))), np.float64)
    index = {name: k for k, name in enumerate(smplx_jax.constants.VERTEX_JOINT_NAMES, start=55)}
    for joint, tip in (("left_index3", rest[index["left_index_tip"]]), ("right_thumb3", rest[index["right_thumb_tip"]]),
                       ("left_eye", rest[index["left_eye_vertex"]]), ("jaw", rest[55 + 21 + 40]),
                       ("right_foot", rest[[index["right_big_toe"], index["right_small_toe"]]].mean(axis=0))):
        j = names.index(joint)
        np.testing.assert_allclose(anim.rest_joints[anim.names.index(joint)] + ends[j], tip, atol=1e-5)


def test_end_sites_of_any_model_file(random_model_dir, monkeypatch):
    """Leaves end at least `MIN_BONE_LENGTH` away, also in a model file whose tip lies on the joint: then the
    bone goes on in its parent's direction."""
    module = importlib.import_module("jaxmocap.export.animation")  # the package's ``animation`` is the function
    model = load(random_model_dir)
    betas = np.zeros(model.num_betas)
    rest = np.asarray(model.joint_template, np.float64)
    monkeypatch.setitem(module.LEAF_TIPS, "jaw", (22,))  # the jaw's own joint
    ends = module.end_sites(model, betas, rest)
    leaves = [j for j in range(55) if j not in model.parents]
    assert len(leaves) == 15 and not ends[[j for j in range(55) if j in model.parents]].any()
    assert (np.linalg.norm(ends[leaves], axis=1) >= module.MIN_BONE_LENGTH).all()
    bone = rest[22] - rest[model.parents[22]]
    np.testing.assert_allclose(np.cross(ends[22], bone), 0, atol=1e-12)
    assert ends[22] @ bone > 0


def test_gltf_is_valid_and_skins_like_the_model(case, tmp_path):
    model, params, motion = case
    anim = animation(model, motion, focal_px=FOCAL)
    doc, binary = read_glb(write_gltf(tmp_path / "motion.glb", model, anim))
    prim = doc["meshes"][0]["primitives"][0]
    positions = accessor(doc, binary, prim["attributes"]["POSITION"]).astype(np.float64)
    joints = accessor(doc, binary, prim["attributes"]["JOINTS_0"])
    weights = accessor(doc, binary, prim["attributes"]["WEIGHTS_0"]).astype(np.float64)
    faces = accessor(doc, binary, prim["indices"]).reshape(-1, 3)
    assert len(positions) == model.num_vertices and faces.max() < len(positions) and joints.max() < 55
    np.testing.assert_allclose(weights.sum(axis=1), 1, atol=1e-6)
    skin = doc["skins"][0]
    assert skin["joints"] == list(range(55)) and doc["nodes"][55]["skin"] == 0
    assert accessor(doc, binary, skin["inverseBindMatrices"]).shape == (55, 16)

    for channel in doc["animations"][0]["channels"]:
        sampler = doc["animations"][0]["samplers"][channel["sampler"]]
        times = accessor(doc, binary, sampler["input"])[:, 0]
        assert len(times) == T and times[-1] == pytest.approx((T - 1) / FPS)
    values = sampled(doc, binary)
    assert len(values) == 56 and all(len(v) == T for v in values.values())

    vertices = np.asarray(FORWARD(model, params).vertices)
    for frame in (0, 6):
        np.testing.assert_allclose(skinned_vertices(doc, binary, 55, frame),
                                   _expected_world(vertices[frame], motion, frame), atol=2e-5)


def test_gltf_passes_the_khronos_validator(case, tmp_path):
    """The Khronos reference validator (npm ``gltf-validator``, installed into the cache on first use) finds no
    error, warning, info or hint in either form of the export."""
    if shutil.which("npm") is None:
        pytest.skip("npm is not on PATH: the Khronos glTF validator cannot be installed (apt-get install nodejs npm)")
    from bench.checks import gltf_validate

    model, _, motion = case
    anim = animation(model, motion, focal_px=FOCAL)
    paths = [write_gltf(tmp_path / name, model, anim) for name in ("motion.glb", "motion.gltf")]
    for path, report in zip(paths, gltf_validate.validate(*paths)):
        assert all(report["issues"][k] == 0 for k in gltf_validate.COUNTS), (path.name, gltf_validate.summary(report))


def test_export_command(case, tmp_path, capsys):
    from jaxmocap.cli import main

    _, _, motion = case
    path = write_motion(tmp_path / "motion.npz", motion)
    for name in ("motion.bvh", "motion.glb", "motion.gltf"):
        fmt = "bvh" if name.endswith("bvh") else "gltf"
        assert main(["export", str(path), "--format", fmt, "--out", str(tmp_path / name)]) == 0
    assert (tmp_path / "motion.bvh").read_text().startswith("HIERARCHY")
    assert json.loads((tmp_path / "motion.gltf").read_text())["buffers"][0]["uri"].startswith("data:")
    assert (tmp_path / "motion.glb").stat().st_mode & 0o777 == 0o644  # readable by others, as open() makes files
    assert not list(tmp_path.glob(".*"))  # no temporary file left
    capsys.readouterr()

    np.savez(tmp_path / "other.npz", **(motion | {"model_sha256": np.array("0" * 64)}))
    np.savez(tmp_path / "partial.npz", **{k: v for k, v in motion.items() if k != "camera_scale"})
    np.savez(tmp_path / "empty.npz", **(motion | {"valid": np.zeros(T, bool)}))
    for bad, message in (("missing.npz", "not found"), ("other.npz", "another body model"),
                         ("partial.npz", "lacks the motion key(s) camera_scale"), ("empty.npz", "no valid frame")):
        assert main(["export", str(tmp_path / bad), "--format", "bvh", "--out", str(tmp_path / "x.bvh")]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    assert not (tmp_path / "x.bvh").exists()
