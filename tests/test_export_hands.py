"""glTF export of a hands.npz: the file skins each valid hand's rest mesh into `hand_meshes`' vertices, placed
where the weak-perspective camera puts the wrist; a hand never valid is left out; no valid hand is an error."""

import json
import shutil

import numpy as np
import pytest

import smplx_jax
from conftest import load
from gltf_util import read_glb, sampled, skinned_vertices
from jaxmocap.export import write_hands_gltf
from jaxmocap.export.animation import CAMERA_TO_WORLD
from jaxmocap.hand_motion import hand_meshes, write_hands
from jaxmocap.result_files import file_sha256
from smplx_jax import SIDES
from smplx_jax.rotations import rotmat_to_rotvec, rotvec_to_rotmat

T, FPS, SIZE, FOCAL = 6, 30.0, (640.0, 480.0), 900.0
INVALID = {"left": 2, "right": 0}  # a frame without the hand
HELD = {"left": (0, 1, 1, 3, 4, 5), "right": (1, 1, 2, 3, 4, 5)}  # the frame whose pose each frame shows


@pytest.fixture(scope="module")
def case(default_model_dir):
    """The default model and a hands file of T frames from random parameters."""
    model = load(default_model_dir)
    rng = np.random.default_rng(7)
    hands = {"fps": np.array(FPS), "image_size": np.array(SIZE),
             "model_sha256": np.array(file_sha256(smplx_jax.default_model_path()))}
    flip = np.asarray(rotvec_to_rotmat(np.array([np.pi, 0.0, 0.0])))  # the image frame: y down
    for side, x in zip(SIDES, (400.0, 200.0)):
        turn = np.asarray(rotvec_to_rotmat(rng.normal(0, 0.7, (T, 3))))
        hands |= {f"{side}_global_orient": np.asarray(rotmat_to_rotvec(flip @ turn)),
                  f"{side}_hand_pose": rng.uniform(-0.6, 0.6, (T, 15, 3)),
                  f"{side}_camera_scale": rng.uniform(1200, 1800, T),
                  f"{side}_camera_trans": np.array([x, 240.0]) + rng.uniform(-40, 40, (T, 2)),
                  f"{side}_valid": np.arange(T) != INVALID[side], f"{side}_keypoints_2d": np.zeros((T, 21, 3)),
                  f"{side}_reprojection_error_px": np.zeros(T)}
    return model, hands


def _expected_world(model, hands, side, frame):
    """Where the exporter's convention puts the side's `hand_meshes` vertices of ``frame`` in the world."""
    hand = smplx_jax.hand_model(model, side)
    vertices = np.asarray(hand_meshes(hand, hands[f"{side}_global_orient"], hands[f"{side}_hand_pose"]).vertices)
    s, t = hands[f"{side}_camera_scale"][frame], hands[f"{side}_camera_trans"][frame]
    wrist = np.concatenate([(t - np.array(SIZE) / 2) / s, [FOCAL / s]])
    return (vertices[frame] + wrist) @ CAMERA_TO_WORLD.T


def test_gltf_skins_like_the_hand_model(case, tmp_path):
    model, hands = case
    doc, binary = read_glb(write_hands_gltf(tmp_path / "hands.glb", model, hands, focal_px=FOCAL))
    assert [m["name"] for m in doc["meshes"]] == ["left_hand", "right_hand"]
    names = [n["name"] for n in doc["nodes"]]
    assert names[:5] == ["left_wrist", "left_index1", "left_index2", "left_index3", "left_middle1"]
    assert names[16] == "left_hand" and names[17] == "right_wrist" and names[-2] == "right_thumb3"
    assert doc["scenes"][0]["nodes"] == [0, 16, 17, 33] and len(doc["skins"]) == 2
    values = sampled(doc, binary)
    assert len(values) == 2 * 17 and all(len(v) == T for v in values.values())

    errors = []
    for side, mesh_node in zip(SIDES, (16, 33)):
        for frame in range(T):
            skinned = skinned_vertices(doc, binary, mesh_node, frame)
            errors.append(np.abs(skinned - _expected_world(model, hands, side, HELD[side][frame])).max())
        wrist_world = values[(mesh_node - 16, "translation")][3]  # the wrist lands on its pixel
        camera = CAMERA_TO_WORLD.T @ wrist_world
        np.testing.assert_allclose(FOCAL * camera[:2] / camera[2] + np.array(SIZE) / 2,
                                   hands[f"{side}_camera_trans"][3], atol=1e-3)
    assert max(errors) < 1e-5, errors


def test_a_hand_never_valid_is_left_out(case, tmp_path):
    model, hands = case
    doc, binary = read_glb(write_hands_gltf(tmp_path / "right.glb", model, hands | {"left_valid": np.zeros(T, bool)}))
    assert [m["name"] for m in doc["meshes"]] == ["right_hand"] and doc["nodes"][0]["name"] == "right_wrist"
    assert len(doc["nodes"]) == 17 and len(sampled(doc, binary)) == 17


def test_gltf_passes_the_khronos_validator(case, tmp_path):
    """As the body's export (tests/test_export.py): no error, warning, info or hint, in both forms."""
    if shutil.which("npm") is None:
        pytest.skip("npm is not on PATH: the Khronos glTF validator cannot be installed (apt-get install nodejs npm)")
    from bench.checks import gltf_validate

    model, hands = case
    paths = [write_hands_gltf(tmp_path / name, model, hands) for name in ("hands.glb", "hands.gltf")]
    for path, report in zip(paths, gltf_validate.validate(*paths)):
        assert all(report["issues"][k] == 0 for k in gltf_validate.COUNTS), (path.name, gltf_validate.summary(report))


def test_export_command(case, tmp_path, capsys):
    from jaxmocap.cli import main

    _, hands = case
    path = write_hands(tmp_path / "hands.npz", hands)
    assert main(["export", str(path), "--format", "gltf", "--out", str(tmp_path / "hands.gltf")]) == 0
    assert json.loads((tmp_path / "hands.gltf").read_text())["meshes"][1]["name"] == "right_hand"
    capsys.readouterr()

    none = write_hands(tmp_path / "none.npz", hands | {f"{side}_valid": np.zeros(T, bool) for side in SIDES})
    for source, fmt, message in ((none, "gltf", "no valid frame"), (path, "bvh", "export the hands as gltf")):
        assert main(["export", str(source), "--format", fmt, "--out", str(tmp_path / "x.out")]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    assert not (tmp_path / "x.out").exists()
