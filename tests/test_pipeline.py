"""End to end: ``jaxmocap run`` on frames of the sample clip — outputs, conventions, resume, bad input."""

import dataclasses
import json
import os
import pickle
import pickletools
import signal
import struct
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest
import smplx
import torch

import frankmocap_reference as ref
import jaxmocap.detect.detector as detector_module
import jaxmocap.pipeline.job as pipeline_job
import jaxmocap.pipeline.regress as regress_module
import jaxmocap.pipeline.stages as stages_module
import smplx_jax
from bench import accuracy
from conftest import (
    assert_kept_for_the_next_process,
    assert_one_body,
    frames_alive_at_each_chunk,
    interrupted_at_chunk,
    temporary_files,
)
from jaxmocap.cli import main
from jaxmocap.errors import InputError
from jaxmocap.export import animation, global_transforms
from jaxmocap.frame_source import open_media
from jaxmocap.integrate import inverse_kinematics
from jaxmocap.motion import MOTION_SHAPES, PINHOLE_SHAPES, WORLD_SHAPES, read_motion
from jaxmocap.pipeline import Observations, RunConfig, whole_clip
from jaxmocap.pipeline.observe import fill_hand_gaps
from jaxmocap.result_files import file_sha256
from smplx_jax import constants
from smplx_jax.rotations import rotvec_to_rotmat

CLIP = Path(__file__).parents[1] / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"
FRAMES, CHUNK = 8, 4  # every run here has the same shapes, so the jitted stages compile once


def run(source, out, **options):
    return pipeline_job.run_bodies(RunConfig(source, **options), out)


@pytest.fixture(scope="module")
def result(tmp_path_factory):
    out = tmp_path_factory.mktemp("run")
    report = run(CLIP, out, start=20, end=20 + FRAMES, chunk_size=CHUNK, exports=("bvh", "gltf"),
                 progress=False, frankmocap_pkl=True, save_frames=True)
    return out, report


def test_motion_schema_and_conventions(result):
    out, report = result
    motion = read_motion(out / "motion.npz")
    assert report.frames == FRAMES and set(motion) == set(MOTION_SHAPES) | set(PINHOLE_SHAPES) | set(WORLD_SHAPES) | {
        "landmark_model"}
    assert str(motion["landmark_model"]) == report.landmarks == "heavy"  # the offline default
    assert motion["valid"].all() and motion["body_pose"].shape == (FRAMES, 21, 3)
    assert tuple(motion["image_size"]) == (1080, 1920) and float(motion["fps"]) == pytest.approx(60.0)
    assert str(motion["model_sha256"]) == file_sha256(smplx_jax.default_model_path())
    assert np.all(motion["reprojection_error_px"] < 25.0)
    # the room's up seen from this camera (its calibration); ours through the default lens, whose focal length is
    # 15% off this camera's: some 3 degrees
    assert np.degrees(np.arccos(motion["floor"][:3] @ accuracy.room_up("cam01"))) < 4.0
    assert motion["contact"].dtype == bool
    # a still camera's turns, measured from the background: none (every frame's camera_from_world the first's)
    np.testing.assert_allclose(motion["camera_from_world"], motion["camera_from_world"][:1].repeat(FRAMES, 0),
                               atol=1e-4)
    names = sorted(p.name for p in (out / "keypoints").iterdir())
    assert names[0] == "pose2sim_single_cam01_000000000020_keypoints.json" and len(names) == FRAMES
    assert not (out / ".jaxmocap_chunks").exists()


def test_the_runs_programs_are_kept_for_the_next_process(result):
    assert_kept_for_the_next_process(whole_clip._fit, inverse_kinematics._ik_batch)


def test_smplx_pytorch_reproduces_the_stored_projections(result):
    """The motion loaded into the PyTorch smplx package, through the stored pinhole camera, gives the stored errors;
    the stored weak-perspective camera is its approximation (at ~2.5 m, parts nearer or farther than the body's
    centre are tens of pixels off)."""
    out, _ = result
    motion = read_motion(out / "motion.npz")
    joints = smplx_joints(motion)[:, constants.OPENPOSE67_FROM_SMPLX]
    assert motion["focal_length"] == pytest.approx(0.75 * 1920)
    assert motion["principal_point"].tolist() == [540, 960]
    assert np.all(joints[..., 2] > 1.0)  # metres in front of the camera
    pixels = motion["focal_length"] * joints[..., :2] / joints[..., 2:] + motion["principal_point"]
    keypoints = motion["keypoints_2d"]
    seen = keypoints[..., 2] > 0
    dist = np.where(seen, np.linalg.norm(pixels - keypoints[..., :2], axis=-1), 0).sum(1) / seen.sum(1)
    np.testing.assert_allclose(dist, motion["reprojection_error_px"], atol=0.01)
    weak = motion["camera_scale"][:, None, None] * joints[..., :2] + motion["camera_trans"][:, None]
    assert np.median(np.linalg.norm(weak - pixels, axis=-1)[seen]) < 40.0


def frankmocap_to_image(points, scale, trans, ratio, top_left, trans_first=False):
    """FrankMocap's ``convert_smpl_to_bbox`` then ``convert_bbox_to_oriIm`` (mocap_utils/coordconv.py), transcribed."""
    data = np.array(points, np.float64)
    if trans_first:  # hand model
        data[:, 0:2] += trans
        data *= scale
    else:
        data *= scale
        data[:, 0:2] += trans
    data *= 224 * 0.5
    data /= ratio
    data[:, :2] += np.asarray(top_left) + 224 * 0.5 / ratio
    return data


PKL_KEYS = ["demo_type", "smpl_type", "image_path", "body_bbox_list", "hand_bbox_list", "save_mesh", "pred_output_list"]
PERSON_SHAPES = {"pred_camera": (3,), "bbox_top_left": (2,), "pred_body_pose": (1, 72), "pred_betas": (1, 10),
                 "pred_body_joints_img": (49, 3), "pred_lhand_joints_img": (21, 3), "pred_rhand_joints_img": (21, 3),
                 "pred_left_hand_pose": (1, 45), "pred_right_hand_pose": (1, 45), "left_hand_local_orient_body": (1, 3),
                 "right_hand_global_orient_body": (1, 3)}


def test_frankmocap_pickles_reproduce_the_projection(result):
    """--frankmocap-pkl: FrankMocap's layout, and its own layer (mean-relative hands, no translation) and camera
    formulas give our stored projection; the files name only what NumPy 1.x (FrankMocap's) can unpickle."""
    out, _ = result
    motion = read_motion(out / "motion.npz")
    files = sorted((out / "mocap").iterdir())
    assert [f.name for f in files] == [f"{20 + t:05d}_prediction_result.pkl" for t in range(FRAMES)]
    data = [pickle.loads(f.read_bytes()) for f in files]
    for t, d in enumerate(data):
        assert list(d) == PKL_KEYS and (d["demo_type"], d["smpl_type"], d["save_mesh"]) == ("frank", "smplx", False)
        assert d["image_path"] == str((out / "frames" / f"{20 + t:05d}.jpg").absolute())
        assert cv2.imread(d["image_path"]).shape == (1920, 1080, 3)  # --save-frames wrote it
        # everyone found: the subject first (the projection below), then the bystander at the back wall
        assert len(d["pred_output_list"]) == len(d["body_bbox_list"]) == len(d["hand_bbox_list"]) in (1, 2)
    assert_frankmocap_projection(data, 0, motion)
    for f in files:
        ops = [(op.name, arg) for op, arg, _ in pickletools.genops(f.read_bytes())]
        modules = {arg.split()[0] for name, arg in ops if name == "GLOBAL"}
        assert "STACK_GLOBAL" not in dict(ops) and modules <= {"numpy", "numpy.core.multiarray", "_codecs",
                                                               "collections"}, modules


def test_frankmocap_pickles_hold_every_person(result, tmp_path):
    """Two people in each frame (the second one 0.4 m to the side and 1 m farther, in a smaller box, hands unseen):
    both in each pickle, the larger box first, each reproducing its own projection through FrankMocap's layer and
    camera formulas."""
    from jaxmocap.export.frankmocap import write_frankmocap_pkls

    out, _ = result
    motion = read_motion(out / "motion.npz")
    data = [pickle.loads(f.read_bytes()) for f in sorted((out / "mocap").iterdir())]

    def xyxy(b):
        return np.concatenate([b[:2], b[:2] + b[2:]]) if b is not None else np.full(4, np.nan)

    body = np.stack([xyxy(d["body_bbox_list"][0]) for d in data])
    hands = np.stack([[xyxy(d["hand_bbox_list"][0][f"{s}_hand"]) for s in ("left", "right")] for d in data])
    other = dict(motion, transl=motion["transl"] + [0.4, 0.0, 1.0])
    smaller = np.concatenate([body[:, :2], body[:, :2] + 0.8 * (body[:, 2:] - body[:, :2])], axis=1)
    people = {0: (motion, body, hands), 1: (other, smaller, np.full_like(hands, np.nan))}
    files = write_frankmocap_pkls(tmp_path, smplx_jax.load_model(smplx_jax.default_model_path()), people,
                                  [tmp_path / f"{t:05d}.jpg" for t in range(FRAMES)])
    both = [pickle.loads(f.read_bytes()) for f in files]
    assert len(both) == FRAMES and all(len(d["pred_output_list"]) == 2 for d in both)
    assert_frankmocap_projection(both, 0, motion)
    assert_frankmocap_projection(both, 1, other)


def assert_frankmocap_projection(data, k, motion):
    """Person ``k`` of each pickle in ``data``: FrankMocap's layout, and its SMPL-X layer and camera formulas put
    its joints where ``motion`` (its frames) puts them with our weak-perspective camera."""
    people = [d["pred_output_list"][k] for d in data]
    for d, person in zip(data, people):
        assert {key: person[key].shape for key in PERSON_SHAPES} == PERSON_SHAPES and "pred_vertices_smpl" not in person
        assert all(person[key].dtype == np.float32 for key in PERSON_SHAPES if key != "bbox_top_left")
        _, ratio, top_left = ref.body_crop(np.zeros((1080, 1920, 3), np.uint8), d["body_bbox_list"][k])
        assert person["bbox_scale_ratio"] == pytest.approx(ratio) and np.array_equal(person["bbox_top_left"], top_left)
    def t(key):
        return torch.from_numpy(np.stack([p[key][0] for p in people]))
    layer = smplx.create(str(smplx_jax.default_model_path().parent.parent), model_type="smplx", use_pca=False,
                         flat_hand_mean=False, num_betas=10, batch_size=len(people))  # FrankMocap's SMPLX layer
    with torch.no_grad():
        joints = layer(global_orient=t("pred_body_pose")[:, :3], body_pose=t("pred_body_pose")[:, 3:66],
                       betas=t("pred_betas"), left_hand_pose=t("pred_left_hand_pose"),
                       right_hand_pose=t("pred_right_hand_pose")).joints.numpy()
    ours = motion["camera_scale"][:, None, None] * smplx_joints(motion)[..., :2] + motion["camera_trans"][:, None]
    for n, person in enumerate(people):
        theirs = frankmocap_to_image(joints[n], person["pred_camera"][0], person["pred_camera"][1:],
                                     person["bbox_scale_ratio"], person["bbox_top_left"])
        np.testing.assert_allclose(theirs[:, :2], ours[n], atol=0.5)
        stored = np.concatenate([person[key] for key in ("pred_body_joints_img", "pred_lhand_joints_img",
                                                         "pred_rhand_joints_img")])
        openpose = np.concatenate([np.arange(25), 49 + np.arange(42)])
        np.testing.assert_allclose(stored[openpose, :2], ours[n, constants.OPENPOSE67_FROM_SMPLX], atol=0.5)
        extra = [27, 28, 37, 39, 40, 41, 42, 43]  # SPIN's hips, neck, pelvis, thorax, spine, jaw, head
        np.testing.assert_allclose(stored[extra, :2], ours[n, [2, 1, 12, 0, 9, 6, 22, 15]], atol=0.5)
        assert np.isfinite(stored).all() and stored[38, 1] < stored[43, 1]  # the top of the head above the head
        for side, index1, ids in (("left", 25, constants.LEFT_HAND21_FROM_SMPLX),
                                  ("right", 40, constants.RIGHT_HAND21_FROM_SMPLX)):
            box = data[n]["hand_bbox_list"][k][f"{side}_hand"]
            if box is None:
                assert person[f"{side}_hand_camera"] is None and person[f"{side}_hand_local_orient_hand"] is None
                continue
            _, ratio, top_left = ref.hand_crop(np.zeros((1080, 1920, 3), np.uint8), box)
            assert person[f"{side}_hand_bbox_scale_ratio"] == pytest.approx(ratio)
            assert tuple(person[f"{side}_hand_bbox_top_left"]) == tuple(top_left)
            hand = frankmocap_to_image(joints[n, list(ids)] - joints[n, index1], person[f"{side}_hand_camera"][0],
                                       person[f"{side}_hand_camera"][1:], ratio, top_left, trans_first=True)
            np.testing.assert_allclose(hand[:, :2], ours[n, list(ids)], atol=0.5)


def smplx_joints(motion):
    """The motion's 127 joints per frame by the PyTorch smplx package (docs/formats.md, "motion.npz")."""
    frames = len(motion["valid"])
    body = smplx.create(str(smplx_jax.default_model_path().parent.parent), model_type="smplx", use_pca=False,
                        flat_hand_mean=True, num_betas=motion["betas"].shape[1], batch_size=frames)
    def t(k):
        return torch.from_numpy(np.ascontiguousarray(motion[k], np.float32)).reshape(frames, -1)
    with torch.no_grad():
        return body(global_orient=t("global_orient"), body_pose=t("body_pose"), left_hand_pose=t("left_hand_pose"),
                    right_hand_pose=t("right_hand_pose"), jaw_pose=t("jaw_pose"), betas=t("betas"),
                    transl=t("transl")).joints.numpy()


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
    _, joints = global_transforms(animation(smplx_jax.load_model(smplx_jax.default_model_path()),
                                            read_motion(out / "motion.npz")))
    assert -0.05 < joints[0, [10, 11], 1].min() < 0.1  # exported in the world frame: the feet on the floor, y = 0


def _no_hand_model(monkeypatch):
    """Any hand model (the detector's, the hand IK, the hand regressor) called from here on fails the test."""
    def refuse(*args, **kwargs):
        raise AssertionError("a hand model ran in --mode body")

    for module, name in ((detector_module, "HandEstimator"), (stages_module, "hand_into_body"),
                         (regress_module, "predict_hands")):
        monkeypatch.setattr(module, name, refuse)


def test_body_mode_runs_no_hand_model_and_is_as_accurate_as_the_whole_mode(result, tmp_path, monkeypatch):
    """``--mode body`` (FrankMocap's body demo): no hand detector, no hand IK; flat, unseen hands; a body as close to
    the take's 3D reference as the whole mode's (frames 20-27, limb joints: PA-MPJPE 50.8 and 51.8 mm measured).
    Their rotations differ by more than their joints' positions: the hands' keypoints and bones decide the forearms'
    twists, which the body's keypoints leave to the priors."""
    _no_hand_model(monkeypatch)
    out, _ = result
    report = run(CLIP, tmp_path, mode="body", start=20, end=20 + FRAMES, chunk_size=CHUNK, overlay=False,
                 progress=False)
    body, whole = read_motion(report.motion), read_motion(out / "motion.npz")
    assert body["valid"].all() and np.all(body["reprojection_error_px"] < 25.0)
    assert not body["left_hand_pose"].any() and not body["right_hand_pose"].any()
    assert not body["keypoints_2d"][:, 25:, 2].any() and whole["keypoints_2d"][:, 25:, 2].any()
    people = [json.loads(p.read_text())["people"] for p in sorted((tmp_path / "keypoints").iterdir())]
    assert len(people) == FRAMES and not any(v for p in people for k in ("hand_left_keypoints_2d",
                                                                          "hand_right_keypoints_2d") for v in p[0][k])
    reference = accuracy.load_reference()[20:20 + FRAMES]
    errors = {name: accuracy.score(accuracy.limb_joints(m), reference)[0].pa_mpjpe_mm
              for name, m in (("body", body), ("whole", whole))}
    print(errors)
    assert errors["body"] <= 60.0 and abs(errors["body"] - errors["whole"]) <= 5.0, errors


def test_interrupted_run_resumes_to_the_same_motion(result, tmp_path, monkeypatch):
    out, _ = result
    with interrupted_at_chunk(monkeypatch, 1), pytest.raises(KeyboardInterrupt):
        run(CLIP, tmp_path, start=20, end=20 + FRAMES, chunk_size=CHUNK, overlay=False, progress=False)
    assert not (tmp_path / "motion.npz").exists() and len(list((tmp_path / ".jaxmocap_chunks").glob("*.npz"))) == 1
    run(CLIP, tmp_path, start=20, end=20 + FRAMES, chunk_size=CHUNK, overlay=False, progress=False)
    assert (tmp_path / "motion.npz").read_bytes() == (out / "motion.npz").read_bytes()


def test_a_panning_camera_turns_the_world_frame_with_it(tmp_path):
    """The clip seen through a window of three quarters of its width sliding 12 px a frame across it (a camera
    panning): each frame's ``camera_from_world`` turns about the image's vertical by the slide's angle through the
    lens, and the run's summary says how far."""
    media, frames = open_media(CLIP, 20, 20 + FRAMES, 1)
    width = int(0.75 * media.size[0])
    video = tmp_path / "pan.mp4"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"mp4v"), media.fps, (width, media.size[1]))
    for k, (_, frame) in enumerate(frames):
        writer.write(np.ascontiguousarray(frame[:, 12 * k:12 * k + width]))
    writer.release()
    report = run(video, tmp_path / "run", chunk_size=CHUNK, overlay=False, progress=False)
    rotations = read_motion(report.motion)["camera_from_world"][:, :3, :3].astype(np.float64)
    turned = np.asarray([cv2.Rodrigues(rotations[0] @ r.T)[0].ravel() for r in rotations])
    slide = np.arctan(12 * np.arange(FRAMES) / (0.75 * media.size[1]))  # through the default lens
    np.testing.assert_allclose(np.linalg.norm(turned, axis=1), slide, atol=np.radians(0.1))
    assert np.all(np.abs(turned[1:, 1]) > 0.99 * np.linalg.norm(turned[1:], axis=1))  # about the vertical
    assert report.camera.startswith(f"camera: turned up to {np.degrees(slide[-1]):.1f} deg")


def test_the_motion_does_not_depend_on_the_chunks(result, tmp_path):
    """The chunks are stored progress, nothing else: the clip in chunks of one frame gives the motion of the clip
    in chunks of `CHUNK` frames bit for bit (the start, the clip fit's windows and the person's shape are placed
    by frame number; a start solved per chunk, in batches of other sizes, rounds otherwise, and the fit's flat
    directions carry that far)."""
    out, _ = result
    report = run(CLIP, tmp_path, start=20, end=20 + FRAMES, chunk_size=1, overlay=False, progress=False)
    single, chunked = read_motion(report.motion), read_motion(out / "motion.npz")
    for key in ("global_orient", "body_pose", "left_hand_pose", "right_hand_pose", "betas", "transl",
                "world_global_orient", "world_transl", "contact"):
        np.testing.assert_array_equal(single[key], chunked[key], err_msg=key)


def test_a_chunks_frames_are_let_go_before_the_next_are_read(tmp_path, monkeypatch):
    """A run holds one chunk of decoded frames at a time (128 frames of 1080p video are 800 MB), so that a long
    video's peak memory is that of a few chunks."""
    with frames_alive_at_each_chunk(monkeypatch) as alive:
        run(CLIP, tmp_path, start=20, end=20 + FRAMES, chunk_size=CHUNK, overlay=False, progress=False)
    assert alive == [0, 0], alive


def test_sigterm_stops_a_run_as_ctrl_c_does(tmp_path, monkeypatch, capsys):
    """SIGTERM (``kill``, ``timeout``, a job scheduler) as the second chunk starts: exit 143 with a one-line note,
    the first chunk stored for the next call, nothing half-written, the process's own SIGTERM handler back after.
    (The test's handler fails it if the signal reaches it during the run; unhandled, it would end the process.)"""
    assert threading.current_thread() is threading.main_thread()  # where signals arrive

    def reached_the_test(signum, frame):
        raise AssertionError("SIGTERM reached the test's handler: the command set none")

    previous = signal.signal(signal.SIGTERM, reached_the_test)
    try:
        with interrupted_at_chunk(monkeypatch, 1, stop=lambda: os.kill(os.getpid(), signal.SIGTERM)):
            code = main(["run", str(CLIP), "--out", str(tmp_path), "--start", "20", "--end", str(20 + FRAMES),
                         "--chunk", str(CHUNK), "--no-overlay", "--quiet"])
        assert signal.getsignal(signal.SIGTERM) is reached_the_test
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert code == 143
    assert capsys.readouterr().err == "jaxmocap run: terminated; run the same command again to resume\n"
    assert not (tmp_path / "motion.npz").exists() and len(list((tmp_path / ".jaxmocap_chunks").glob("*.npz"))) == 1
    assert not temporary_files(tmp_path)


def test_clip_without_people(tmp_path):
    path = tmp_path / "empty.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (320, 240))
    for k in range(FRAMES):
        writer.write(np.full((240, 320, 3), 40 + 10 * k, np.uint8))
    writer.release()
    report = run(path, tmp_path / "out", chunk_size=CHUNK, exports=("bvh",), progress=False)
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


def _clip_frames(first, last):
    return [frame for _, frame in open_media(CLIP, first, last, 1)[1]]


def _reference_body_rotmats(body_net, frame, box_xywh):
    """The PyTorch reference HMR on FrankMocap's (transcribed) crop of ``box_xywh``: SMPL's 24 rotations."""
    crop, _, _ = ref.body_crop(frame, box_xywh)
    image = (crop[..., ::-1] / 255.0 - [0.485, 0.456, 0.406]) / [0.229, 0.224, 0.225]  # RGB, ImageNet's statistics
    with torch.no_grad():
        return body_net(torch.from_numpy(image.astype(np.float32)).permute(2, 0, 1)[None])[0][0].numpy()


def _reference_hand(hand_net, frame, box_xywh, side):
    """The PyTorch reference hand network on FrankMocap's crop of ``box_xywh`` (a left hand's flipped, predicted as
    a right one and mirrored back): the absolute hand pose of that side."""
    crop, _, _ = ref.hand_crop(frame, box_xywh)
    crop = crop[:, ::-1] if side == "left" else crop
    with torch.no_grad():
        raw = hand_net(torch.from_numpy((crop / 255.0 - 0.5) / 0.5).float().permute(2, 0, 1)[None])[0].numpy()
    relative = raw[6:51].reshape(15, 3) * ([1, -1, -1] if side == "left" else 1)
    model = smplx_jax.load_model(smplx_jax.default_model_path())
    return relative + np.asarray(model.hand_mean[("left", "right").index(side)]).reshape(15, 3)


def test_copy_paste_motion_is_the_regressors_output(frankmocap, frankmocap_run):
    """``--weights --integration copy-paste`` (no smoothing): in each frame the body is the reference HMR's
    prediction on FrankMocap's crop of the frame's body box, the right hand's fingers the reference hand network's
    on its box (the boxes FrankMocap's pickles record)."""
    _, hand_net, body_net = frankmocap
    out = frankmocap_run(integration="copy-paste")
    motion = read_motion(out / "motion.npz")
    assert motion["valid"].all()
    pickles = [pickle.loads(f.read_bytes()) for f in sorted((out / "mocap").iterdir())]
    body_joints = [j for j in range(21) if j + 1 not in (constants.LEFT_WRIST, constants.RIGHT_WRIST)]
    hands = 0
    for t, (frame, d) in enumerate(zip(_clip_frames(20, 20 + FRAMES), pickles, strict=True)):
        rotmats = _reference_body_rotmats(body_net, frame, d["body_bbox_list"][0])
        ours = np.asarray(rotvec_to_rotmat(motion["body_pose"][t]))
        assert np.abs(ours[body_joints] - rotmats[1:22][body_joints]).max() < 2e-3, t
        for side in ("left", "right"):
            box = d["hand_bbox_list"][0][f"{side}_hand"]
            if box is not None:
                hands += 1
                np.testing.assert_allclose(motion[f"{side}_hand_pose"][t],
                                           _reference_hand(hand_net, frame, box, side), atol=2e-3)
    seen = [(motion["keypoints_2d"][:, hand, 2] > 0).any(axis=1) for hand in (slice(25, 46), slice(46, 67))]
    assert hands == np.sum(seen) >= 1  # every hand the detector found
    assert_one_body(motion)  # the median of the regressor's shapes


def test_optimize_fits_the_keypoints_better_than_copy_paste(frankmocap_run):
    """From the random regressors' copy-and-paste bodies (hundreds of pixels off), the fit comes to the keypoints."""
    errors = {integration: read_motion(frankmocap_run(integration=integration) / "motion.npz")
              for integration in ("copy-paste", "optimize")}
    copy, fitted = (errors[k]["reprojection_error_px"] for k in ("copy-paste", "optimize"))
    print("copy-paste", np.round(copy, 1), "optimize", np.round(fitted, 1))  # measured: at most 0.26 times
    assert errors["optimize"]["valid"].all() and np.all(fitted < 0.4 * copy)
    assert_one_body(errors["optimize"])


@pytest.mark.parametrize("hand_boxes, mode", [("body", "whole"), ("keypoints", "body")])
def test_frankmocap_path_without_the_hand_detector(frankmocap, frankmocap_run, monkeypatch, hand_boxes, mode):
    """``--hand-boxes body``: the hand detector is skipped and the body's hands give boxes inside the image;
    ``--mode body``: the body regressor alone runs (FrankMocap's body demo), the hands flat. The body is the
    reference HMR's prediction either way."""
    if mode == "body":
        _no_hand_model(monkeypatch)
    out = frankmocap_run(integration="copy-paste", hand_boxes=hand_boxes, mode=mode)
    motion = read_motion(out / "motion.npz")
    assert motion["valid"].all() and not motion["keypoints_2d"][:, 25:, 2].any()  # no hand detection
    pickles = [pickle.loads(f.read_bytes()) for f in sorted((out / "mocap").iterdir())]
    frame = _clip_frames(20, 21)[0]
    rotmats = _reference_body_rotmats(frankmocap[2], frame, pickles[0]["body_bbox_list"][0])
    assert np.abs(np.asarray(rotvec_to_rotmat(motion["body_pose"][0]))[:19] - rotmats[1:20]).max() < 2e-3
    if mode == "body":
        assert not motion["left_hand_pose"].any() and not motion["right_hand_pose"].any()
        return
    boxes = [p["hand_bbox_list"][0] for p in pickles]
    xywh = np.array([[b[side] for side in ("left_hand", "right_hand")] for b in boxes], np.float64)
    assert xywh.shape == (FRAMES, 2, 4) and np.isfinite(xywh).all()
    assert np.all(xywh[..., :2] >= 0) and np.all(xywh[..., :2] + xywh[..., 2:] <= (1080, 1920))
    own = _reference_hand(frankmocap[1], frame, boxes[0]["right_hand"], "right")
    np.testing.assert_allclose(motion["right_hand_pose"][0], own, atol=2e-3)


def test_body_hand_boxes_need_weights(tmp_path, capsys):
    code = main(["run", str(CLIP), "--hand-boxes", "body", "--out", str(tmp_path / "o"), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--weights" in err


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
    report = run(CLIP, tmp_path / "out", keypoints=moved, start=20, end=20 + FRAMES,
                              chunk_size=CHUNK, overlay=False, progress=False)
    original, shifted = read_motion(out / "motion.npz"), read_motion(report.motion)
    seen = original["keypoints_2d"][..., 2] > 0
    np.testing.assert_allclose(shifted["keypoints_2d"][..., 0][seen], original["keypoints_2d"][..., 0][seen] + 30,
                               atol=1e-2)
    # the body follows them: on its shifted targets as close as the original on its own (30 px off, were it not)
    errors = [np.median(m["reprojection_error_px"]) for m in (original, shifted)]
    assert errors[1] < errors[0] + 3.0, errors


def test_a_hand_lost_for_a_short_gap_is_interpolated():
    n = 20
    hands_conf = np.zeros((n, 2))
    hands_conf[[0, 4, 15], 0] = 1.0  # left: a gap of 3 frames, then one of 10
    hands_conf[[6, 10], 1] = 1.0  # right: a gap of 3 frames without the person in one
    keypoints = np.zeros((n, 67, 3))
    keypoints[[0, 4, 15], 25:46] = [[10.0, 20.0, 0.9]], [[50.0, 60.0, 0.5]], [[0.0, 0.0, 1.0]]
    keypoints[4, 30, 2] = 0.0  # one keypoint unseen at the gap's end
    hands_world = np.zeros((n, 2, 21, 3))
    hands_world[4, 0] = 0.04
    found = np.ones(n, bool)
    found[8] = False
    obs = Observations(keypoints, np.zeros((n, 33, 4)), hands_world, hands_conf, np.zeros((n, 4)),
                       np.zeros((n, 2, 4)), found)
    filled = fill_hand_gaps(obs, max_gap=3)
    np.testing.assert_allclose(filled.keypoints[1:4, 25], [[20, 30, 0.8], [30, 40, 0.7], [40, 50, 0.6]])
    np.testing.assert_allclose(filled.hands_world[1:4, 0, 5], [[0.01] * 3, [0.02] * 3, [0.03] * 3])
    np.testing.assert_allclose(filled.hands_conf[1:4, 0], 1.0)
    assert np.all(filled.keypoints[1:4, 30] == 0)  # seen at one end only
    assert np.all(filled.hands_conf[5:15, 0] == 0) and np.all(filled.keypoints[5:15] == 0)  # too long
    assert np.all(filled.hands_conf[7:10, 1] == 0)  # the person was lost in between


def test_left_and_right_exchanged_by_the_detector_are_put_back():
    """Real detections of the sample clip, with arms exchanged in frames 10-19 and legs in 12-25 as a detector
    does when it loses track of the sides: the repair gives back the detections, at once or in two chunks (the
    second from the first's last frame); it leaves them alone as they are."""
    from jaxmocap.detect import Detector
    from jaxmocap.frame_source import open_media
    from jaxmocap.pipeline.observe import _ARMS, _LEGS, _swap_sides, observe, repair_side_swaps

    _, frames = open_media(CLIP, 20, 50, 1)
    obs = observe(Detector(static_image_mode=False), [frame for _, frame in frames])
    assert obs.found.all() and (obs.hands_conf > 0).any()
    swapped = repair_side_swaps(obs)  # a copy with the same arrays
    for t in range(10, 20):
        _swap_sides(swapped, t, _ARMS)
    for t in range(12, 26):
        _swap_sides(swapped, t, _LEGS)
    assert not np.array_equal(swapped.keypoints, obs.keypoints)
    first, second = (dataclasses.replace(swapped, **{k: getattr(swapped, k)[part] for k in (
        "keypoints", "body_world", "hands_world", "hands_conf", "body_box", "hand_boxes", "found")})
        for part in (slice(0, 15), slice(15, None)))
    head = repair_side_swaps(first)
    in_chunks = repair_side_swaps(second, head.keypoints[-1])  # a chunk boundary inside both swaps
    for repaired in (repair_side_swaps(swapped), repair_side_swaps(obs)):
        for key in ("keypoints", "body_world", "hands_world", "hands_conf", "hand_boxes"):
            np.testing.assert_array_equal(getattr(repaired, key), getattr(obs, key), err_msg=key)
    for key in ("keypoints", "body_world", "hands_world", "hands_conf", "hand_boxes"):
        np.testing.assert_array_equal(np.concatenate([getattr(head, key), getattr(in_chunks, key)]),
                                      getattr(obs, key), err_msg=key)


def test_every_option_that_shapes_a_chunk_keys_the_store(tmp_path):
    """A stored chunk is reused only under the same options: each option (but those used after the last chunk)
    changes the key, and so do the contents of the input files; the outputs asked for do not."""
    from jaxmocap.pipeline.config import AT_THE_END, chunk_key

    (tmp_path / "weights").mkdir()
    (tmp_path / "weights" / "regressors.json").write_text("{}")
    (tmp_path / "keypoints").mkdir()
    other = tmp_path / "other.mp4"
    other.write_bytes(CLIP.read_bytes())
    variants = dict(source=other, model=None, weights=tmp_path / "weights", integration="copy-paste",
                    hand_boxes="body", keypoints=tmp_path / "keypoints", start=1, end=9, stride=2, chunk_size=64,
                    iterations=5, focal_length=1000.0, max_people=2, mode="body", max_hands=3,
                    landmarks="lite", camera="static")
    keyed = {f.name for f in dataclasses.fields(RunConfig) if f.metadata != AT_THE_END}
    assert set(variants) == keyed
    for name, value in variants.items():
        options = dict(source=CLIP) | (dict(weights=tmp_path / "weights") if name in ("integration", "hand_boxes")
                                       else {})
        changed = chunk_key(RunConfig(**options | {name: value}), "other-sha" if name == "model" else "model-sha")
        assert changed != chunk_key(RunConfig(**options), "model-sha"), name
    assert chunk_key(RunConfig(CLIP, smooth=False, overlay=False, exports=("bvh",), frankmocap_pkl=True,
                               progress=False), "model-sha") == chunk_key(RunConfig(CLIP), "model-sha")
    key = chunk_key(RunConfig(other), "model-sha")
    other.write_bytes(CLIP.read_bytes()[:-1])  # the same path, another video
    assert chunk_key(RunConfig(other), "model-sha") != key


@pytest.mark.parametrize("options, message", [
    (dict(integration="eft"), "needs --weights"), (dict(integration="magic"), "unknown integration"),
    (dict(hand_boxes="body"), "needs --weights"), (dict(focal_length=-3.0), "focal-length must be positive"),
    (dict(exports=("fbx",)), "unknown export format"), (dict(chunk_size=0), "chunk-size must be positive"),
    (dict(max_people=0), "max-people must be positive"), (dict(max_hands=0), "max-hands must be positive"),
    (dict(mode="feet"), "unknown mode 'feet'"), (dict(landmarks="huge"), "unknown landmark model 'huge'"),
    (dict(camera="dolly"), "unknown camera 'dolly'"),
    (dict(mode="hands", keypoints=Path("k")), "hands does not take --keypoints"),
    (dict(mode="hands", weights=Path("w"), integration="eft"), "hands does not take --integration eft"),
    (dict(mode="hands", weights=Path("w"), hand_boxes="body"), "hands does not take --hand-boxes body"),
    (dict(mode="body", weights=Path("w"), hand_boxes="body"), "body does not take --hand-boxes body"),
])
def test_run_config_refuses_what_cannot_run(options, message):
    with pytest.raises(InputError, match=message):
        RunConfig(CLIP, **options)
