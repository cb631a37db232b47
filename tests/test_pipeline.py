"""End to end: ``jaxmocap run`` on frames of the sample clip — outputs, conventions, resume, bad input."""

import json
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest
import smplx
import torch

import frankmocap_reference as ref
import jaxmocap.pipeline.job as pipeline_run
import smplx_jax
from jaxmocap.cli import main
from jaxmocap.io import file_sha256
from jaxmocap.motion import MOTION_SHAPES, read_motion
from smplx_jax import constants

CLIP = Path(__file__).parents[1] / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"
FRAMES, CHUNK = 8, 4  # every run here has the same shapes, so the jitted stages compile once


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    report = pipeline_run.run(CLIP, out, start=20, end=20 + FRAMES, chunk_size=CHUNK, exports=("bvh", "gltf"),
                              progress=False)
    return out, report


def test_motion_schema_and_conventions(result):
    out, report = result
    motion = read_motion(out / "motion.npz")
    assert report.frames == FRAMES and set(motion) == set(MOTION_SHAPES)
    assert motion["valid"].all() and motion["body_pose"].shape == (FRAMES, 21, 3)
    assert tuple(motion["image_size"]) == (1080, 1920) and float(motion["fps"]) == pytest.approx(60.0)
    assert str(motion["model_sha256"]) == file_sha256(smplx_jax.default_model_path())
    assert np.all(motion["reprojection_error_px"] < 25.0)
    names = sorted(p.name for p in (out / "keypoints").iterdir())
    assert names[0] == "pose2sim_single_cam01_000000000020_keypoints.json" and len(names) == FRAMES
    assert not (out / ".jaxmocap_chunks").exists()


def test_smplx_pytorch_reproduces_the_stored_projections(result):
    """The motion loaded into the PyTorch smplx package with the stored camera gives the stored errors."""
    out, _ = result
    motion = read_motion(out / "motion.npz")
    body = smplx.create(str(smplx_jax.default_model_path().parent.parent), model_type="smplx", use_pca=False,
                        flat_hand_mean=True, num_betas=motion["betas"].shape[1], batch_size=FRAMES)
    t = lambda k: torch.from_numpy(np.ascontiguousarray(motion[k], np.float32)).reshape(FRAMES, -1)  # noqa: E731
    with torch.no_grad():
        joints = body(global_orient=t("global_orient"), body_pose=t("body_pose"), left_hand_pose=t("left_hand_pose"),
                      right_hand_pose=t("right_hand_pose"), jaw_pose=t("jaw_pose"), betas=t("betas"),
                      transl=t("transl")).joints.numpy()
    pixels = motion["camera_scale"][:, None, None] * joints[:, constants.OPENPOSE67_FROM_SMPLX, :2]
    pixels += motion["camera_trans"][:, None]
    keypoints = motion["keypoints_2d"]
    seen = keypoints[..., 2] > 0
    dist = np.where(seen, np.linalg.norm(pixels - keypoints[..., :2], axis=-1), 0).sum(1) / seen.sum(1)
    np.testing.assert_allclose(dist, motion["reprojection_error_px"], atol=0.01)


def test_overlay_and_exports(result):
    out, _ = result
    video = cv2.VideoCapture(str(out / "overlay.mp4"))
    assert int(video.get(cv2.CAP_PROP_FRAME_COUNT)) == FRAMES
    ok, frame = video.read()
    assert ok and frame.shape == (960, 1080, 3)
    text = (out / "motion.bvh").read_text()
    assert f"Frames: {FRAMES}" in text and text.count("JOINT") == 54
    data = (out / "motion.glb").read_bytes()
    assert data[:4] == b"glTF" and struct.unpack_from("<I", data, 8)[0] == len(data)
    doc = json.loads(data[20:20 + struct.unpack_from("<I", data, 12)[0]])
    times = doc["accessors"][doc["animations"][0]["samplers"][0]["input"]]
    assert times["count"] == FRAMES and times["max"][0] == pytest.approx((FRAMES - 1) / 60.0)


def test_interrupted_run_resumes_to_the_same_motion(result, tmp_path, monkeypatch):
    out, _ = result
    solve, calls = pipeline_run._solve, []

    def interrupted(*args):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return solve(*args)

    monkeypatch.setattr(pipeline_run, "_solve", interrupted)
    with pytest.raises(KeyboardInterrupt):
        pipeline_run.run(CLIP, tmp_path, start=20, end=20 + FRAMES, chunk_size=CHUNK, overlay=False, progress=False)
    assert not (tmp_path / "motion.npz").exists() and len(list((tmp_path / ".jaxmocap_chunks").glob("*.npz"))) == 1
    monkeypatch.setattr(pipeline_run, "_solve", solve)
    pipeline_run.run(CLIP, tmp_path, start=20, end=20 + FRAMES, chunk_size=CHUNK, overlay=False, progress=False)
    assert (tmp_path / "motion.npz").read_bytes() == (out / "motion.npz").read_bytes()


def test_clip_without_people(tmp_path):
    path = tmp_path / "empty.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (320, 240))
    for k in range(FRAMES):
        writer.write(np.full((240, 320, 3), 40 + 10 * k, np.uint8))
    writer.release()
    report = pipeline_run.run(path, tmp_path / "out", chunk_size=CHUNK, exports=("bvh",), progress=False)
    motion = read_motion(report.motion)
    assert report.frames == FRAMES and not motion["valid"].any()
    assert not (tmp_path / "out" / "motion.bvh").exists()  # nothing to animate
    people = json.loads(next((tmp_path / "out" / "keypoints").iterdir()).read_text())["people"]
    assert people == []


@pytest.mark.parametrize("args, message", [
    (["run", "missing.mp4"], "does not exist"),
    (["run", "not_a_video.mp4"], "cannot open"),
    (["run", "zero.avi"], "no readable frames"),
    (["run", str(CLIP), "--model", "bad_model.npz"], "not a readable .npz"),
    (["run", str(CLIP), "--export", "fbx"], "unknown export format"),
    (["run", str(CLIP), "--out", "blocker/out"], "blocker"),
])
def test_bad_input_is_one_line(tmp_path, capsys, monkeypatch, args, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "not_a_video.mp4").write_bytes(b"definitely not a video")
    (tmp_path / "bad_model.npz").write_bytes(b"PK junk")
    (tmp_path / "blocker").write_text("")
    cv2.VideoWriter(str(tmp_path / "zero.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (64, 64)).release()
    code = main(args + (["--out", "o"] if "--out" not in args else []) + ["--quiet", "--end", "2"])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1


@pytest.mark.parametrize("integration", ["copy-paste", "optimize"])
def test_frankmocap_path_with_converted_weights(tmp_path, integration):
    """Random FrankMocap-format checkpoints -> convert-frankmocap -> run --weights: a motion for every frame."""
    ref.write_checkpoints(tmp_path)
    assert main(["convert-frankmocap", "--hand", str(tmp_path / "pose_shape_best.pth"), "--hand-mean",
                 str(tmp_path / "mean_mano_params.pkl"), "--body", str(tmp_path / "body.pt"), "--out",
                 str(tmp_path / "weights")]) == 0
    report = pipeline_run.run(CLIP, tmp_path / "out", weights=tmp_path / "weights", integration=integration,
                              start=20, end=20 + FRAMES, chunk_size=CHUNK, overlay=False, progress=False)
    motion = read_motion(report.motion)
    assert motion["valid"].all() and np.all(np.isfinite(motion["body_pose"]))
    assert np.all(motion["camera_scale"] > 0)


def test_weights_of_another_architecture_are_refused(tmp_path, capsys):
    (tmp_path / "weights").mkdir()
    (tmp_path / "weights" / "regressors.json").write_text('{"format": "something-else"}')
    code = main(["run", str(CLIP), "--weights", str(tmp_path / "weights"), "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "regressors.json" in err


def test_given_keypoints_replace_the_detectors(result, tmp_path):
    """--keypoints: OpenPose JSON (here the run's own detections moved 30 px right) are the fit's targets."""
    out, _ = result
    moved = tmp_path / "moved"
    moved.mkdir()
    for path in (out / "keypoints").iterdir():
        doc = json.loads(path.read_text())
        for person in doc["people"]:
            for key in ("pose_keypoints_2d", "hand_left_keypoints_2d", "hand_right_keypoints_2d"):
                flat = person[key]
                person[key] = [v + 30.0 if k % 3 == 0 and flat[k + 2] > 0 else v for k, v in enumerate(flat)]
        (moved / path.name).write_text(json.dumps(doc))
    report = pipeline_run.run(CLIP, tmp_path / "out", keypoints_dir=moved, start=20, end=20 + FRAMES,
                              chunk_size=CHUNK, overlay=False, progress=False)
    original, shifted = read_motion(out / "motion.npz"), read_motion(report.motion)
    seen = original["keypoints_2d"][..., 2] > 0
    np.testing.assert_allclose(shifted["keypoints_2d"][..., 0][seen], original["keypoints_2d"][..., 0][seen] + 30,
                               atol=1e-2)
    assert np.median(shifted["camera_trans"][:, 0] - original["camera_trans"][:, 0]) > 20
