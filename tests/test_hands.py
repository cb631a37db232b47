"""Hands on their own (``--mode hands``): a real close-up (OpenCV's sample), its mirror image, two hands, none, a
hand close-up video of the bundled clip (tracking, resume), FrankMocap's hand regressor, and hands.npz re-posed by
the PyTorch ``smplx`` package. One compiled fit serves every test (`hand_fit.BUCKETS`)."""

import hashlib
import json
import socket
from pathlib import Path

import cv2
import jax
import numpy as np
import pytest
import smplx
import torch

import smplx_jax
from conftest import assert_kept_for_the_next_process, frames_alive_at_each_chunk
from jaxmocap.cli import main
from jaxmocap.detect.hand_tracker import HandTracker
from jaxmocap.hand_motion import hand_meshes, read_hands
from jaxmocap.integrate import hand_fit
from jaxmocap.integrate.hand_fit import fit_hands
from jaxmocap.pipeline import RunConfig, run
from smplx_jax import constants

DATA = Path(__file__).parent / "data"
CLOSEUP = DATA / "opencv_handSrc.jpg"
CLIP = DATA / "pose2sim_hand_closeup.mp4"
MODEL = smplx_jax.load_model(smplx_jax.default_model_path())


def box_size(keypoints: np.ndarray) -> np.ndarray:
    """(T,) the longer side of each frame's keypoint box, pixels."""
    return np.maximum(np.ptp(keypoints[..., 0], axis=-1), np.ptp(keypoints[..., 1], axis=-1))


@pytest.fixture(scope="module")
def still(tmp_path_factory):
    out = tmp_path_factory.mktemp("still")
    report = run(RunConfig(CLOSEUP, mode="hands", exports=("gltf",), progress=False), out)
    return out, report, read_hands(out / "hands.npz")


def test_close_up_sample_is_one_left_hand_fitted_within_3_percent_of_its_size(still):
    out, report, hands = still
    assert report.frames == 1 and report.valid == 1 and report.people == [0]
    assert hands["left_valid"].tolist() == [True] and hands["right_valid"].tolist() == [False]
    error = hands["left_reprojection_error_px"][0]
    assert 0 < error <= 0.03 * box_size(hands["left_keypoints_2d"])[0]
    assert hands["image_size"].tolist() == [640, 480] and (out / "hands.glb").stat().st_size > 10_000


def test_close_up_joints_land_where_hands_npz_says(still):
    """pixel = camera_scale * X[:2] + camera_trans with X the hand model H's joints (wrist at the origin): their
    mean distance to the keypoints is the stored reprojection error."""
    _, _, hands = still
    joints = np.asarray(hand_meshes(smplx_jax.hand_model(MODEL, "left"), hands["left_global_orient"],
                                    hands["left_hand_pose"]).joints)
    pixels = hands["left_camera_scale"][:, None, None] * joints[..., :2] + hands["left_camera_trans"][:, None]
    distance = np.linalg.norm(pixels - hands["left_keypoints_2d"][..., :2], axis=-1).mean()
    assert distance == pytest.approx(hands["left_reprojection_error_px"][0], abs=0.05)


def test_hands_npz_reposed_by_pytorch_smplx(still, default_model_dir):
    """The PyTorch package's SMPL-X (flat hand mean, no PCA), at rest but for the wrist (global_orient) and the
    fingers (hand_pose), gives the same hand joints as hands.npz's projection rule says."""
    _, _, hands = still
    body = smplx.create(str(default_model_dir), model_type="smplx", use_pca=False, flat_hand_mean=True)
    body_pose = torch.zeros(1, 21, 3)
    body_pose[0, constants.LEFT_WRIST - 1] = torch.tensor(hands["left_global_orient"][0])
    with torch.no_grad():
        joints = body(body_pose=body_pose.reshape(1, 63),
                      left_hand_pose=torch.tensor(hands["left_hand_pose"][0]).reshape(1, 45)).joints[0].numpy()
    hand = joints[list(constants.LEFT_HAND21_FROM_SMPLX)] - joints[constants.LEFT_WRIST]
    ours = np.asarray(hand_meshes(smplx_jax.hand_model(MODEL, "left"), hands["left_global_orient"],
                                  hands["left_hand_pose"]).joints)[0]
    np.testing.assert_allclose(hand, ours, atol=1e-5)
    pixels = hands["left_camera_scale"][0] * hand[:, :2] + hands["left_camera_trans"][0]
    error = np.linalg.norm(pixels - hands["left_keypoints_2d"][0, :, :2], axis=-1).mean()
    assert error == pytest.approx(hands["left_reprojection_error_px"][0], abs=0.05)


def test_close_up_overlay_draws_the_mesh_on_the_hand(still):
    out, _, hands = still
    ok, frame = cv2.VideoCapture(str(out / "overlay.mp4")).read()
    assert ok and frame.shape == (480, 1280, 3)
    changed = np.abs(frame[:, :640].astype(int) - cv2.imread(str(CLOSEUP)).astype(int)).max(axis=2) > 20
    hull = np.zeros((480, 640), np.uint8)
    cv2.fillConvexPoly(hull, cv2.convexHull(hands["left_keypoints_2d"][0, :, :2].astype(np.int32)), 1)
    grown = cv2.dilate(hull, np.ones((61, 61), np.uint8)) > 0
    assert changed[hull > 0].mean() > 0.6  # the palm and fingers are painted over...
    assert changed[~grown].mean() < 0.08  # ...and little far from it (the forearm's stump at the wrist, mp4 noise)


def test_close_up_openpose_json_is_hands_only(still):
    out, _, _ = still
    people = json.loads((out / "keypoints" / "opencv_handSrc_keypoints.json").read_text())["people"]
    assert len(people) == 1 and people[0]["pose_keypoints_2d"] == []
    assert min(people[0]["hand_left_keypoints_2d"][2::3]) > 0.5 and not any(people[0]["hand_right_keypoints_2d"])


def test_mirrored_image_swaps_the_side_and_mirrors_the_fit():
    tracker = HandTracker(static_image_mode=True)
    image = cv2.imread(str(CLOSEUP))
    fits = {}
    for picture in (image, np.ascontiguousarray(image[:, ::-1])):
        (hand,) = tracker(picture)
        keypoints = hand.keypoints_2d
        fit = fit_hands(MODEL, hand.side, hand.world[None], np.ones((1, 21)), keypoints[None])
        joints = hand_meshes(smplx_jax.hand_model(MODEL, hand.side), fit.global_orient, fit.hand_pose).joints
        fits[hand.side] = (np.asarray(joints)[0], keypoints)
    assert set(fits) == {"left", "right"}
    (left, left_2d), (right, right_2d) = fits["left"], fits["right"]
    np.testing.assert_allclose(right_2d[:, 0], image.shape[1] - 1 - left_2d[:, 0], atol=12.0)  # the detection...
    assert np.abs(right * [-1, 1, 1] - left).max() < 0.01  # ...and the 3D hand, mirrored (to 1 cm)


def test_two_hands_are_a_left_and_a_right(tmp_path):
    """Both hands, and with ``--max-hands`` above 2 each hand's own file and JSON person."""
    image = cv2.imread(str(CLOSEUP))
    cv2.imwrite(str(tmp_path / "two.png"), np.concatenate([image, image[:, ::-1]], axis=1))
    run(RunConfig(tmp_path / "two.png", mode="hands", max_hands=3, overlay=False, progress=False), tmp_path / "out")
    hands = read_hands(tmp_path / "out" / "hands.npz")
    assert hands["left_valid"][0] and hands["right_valid"][0]
    assert hands["left_keypoints_2d"][0, :, 0].max() < 640 <= hands["right_keypoints_2d"][0, :, 0].min()
    for side in ("left", "right"):
        assert hands[f"{side}_reprojection_error_px"][0] <= 0.03 * box_size(hands[f"{side}_keypoints_2d"])[0]
    own = [read_hands(tmp_path / "out" / "hands" / f"{i}.npz") for i in (0, 1)]
    assert sorted((h["left_valid"][0], h["right_valid"][0]) for h in own) == [(False, True), (True, False)]
    people = json.loads((tmp_path / "out" / "keypoints" / "two_keypoints.json").read_text())["people"]
    assert sorted(p["person_id"][0] for p in people) == [0, 1]
    assert all(bool(any(p["hand_left_keypoints_2d"])) != bool(any(p["hand_right_keypoints_2d"])) for p in people)


def test_no_hand_is_not_valid_and_exits_0(tmp_path, capsys):
    wall = cv2.imread(str(DATA / "pose2sim_cam01_f000.jpg"))[:200, :200]
    cv2.imwrite(str(tmp_path / "wall.png"), wall)
    assert main(["run", str(tmp_path / "wall.png"), "--mode", "hands", "--out", str(tmp_path / "o"), "--quiet"]) == 0
    hands = read_hands(tmp_path / "o" / "hands.npz")
    assert not hands["left_valid"].any() and not hands["right_valid"].any()
    assert "0 with a hand" in capsys.readouterr().out
    assert json.loads((tmp_path / "o" / "keypoints" / "wall_keypoints.json").read_text())["people"] == []


@pytest.fixture(scope="module")
def video(tmp_path_factory):
    out = tmp_path_factory.mktemp("video")
    report = run(RunConfig(CLIP, mode="hands", end=32, chunk_size=16, progress=False), out)
    return out, report, read_hands(out / "hands.npz")


def test_close_up_video_is_tracked_and_fitted_within_3_percent(video):
    """The right hand of the bundled clip, cropped: found and fitted in 20 of the 32 frames or more (mediapipe's
    hand solution finds it in 21: it is blurred in 17-28), one identity throughout (found again where it was
    lost), the median error within 3% of its size."""
    out, report, hands = video
    valid = hands["right_valid"]
    assert report.frames == 32 and valid.sum() >= 20 and not hands["left_valid"].any() and report.people == [0]
    errors = hands["right_reprojection_error_px"][valid] / box_size(hands["right_keypoints_2d"][valid])
    assert np.median(errors) <= 0.03 and np.all(np.isfinite(hands["right_hand_pose"]))
    assert len(list((out / "keypoints").glob("*.json"))) == 32 and (out / "overlay.mp4").stat().st_size > 0
    assert_kept_for_the_next_process(hand_fit._fit_batch)


@pytest.mark.parametrize("version", ["as shot", "blurred", "mirrored, blurred"])
def test_a_hand_is_found_in_every_frame_where_mediapipe_finds_one(version):
    """The hand close-up video as shot, blurred by 2 px and mirrored (a left hand) and blurred, tracked as a hands
    run tracks it (up to two hands): a hand in every frame where mediapipe's hand solution, given the same frames,
    finds one (`tests/data/record_mediapipe_golden.py`), and never two: where mediapipe reports a second hand laid
    over the first (as shot, 62-66: a palm detection on its fingers), it is reported once. Blurred, the hand is
    lost for a frame in 17 and 21, found again at once by the palm detector or the second track, as mediapipe's."""
    golden = json.loads((DATA / "mediapipe_golden.json").read_text())["videos"][CLIP.name][version]
    capture, frames = cv2.VideoCapture(str(CLIP)), []
    while (frame := capture.read()[1]) is not None:
        frames.append(frame)
    blurred = version != "as shot"
    frames = [cv2.GaussianBlur(cv2.flip(f, 1) if version.startswith("mirrored") else f, (0, 0), 2.0) if blurred
              else f for f in frames]
    assert hashlib.sha256(b"".join(f.tobytes() for f in frames)).hexdigest() == golden["pixels_sha256"]
    tracker = HandTracker(static_image_mode=False, max_hands=2)
    found = np.array([len(tracker(frame)) for frame in frames])
    theirs = np.array(golden["hands_per_frame"]) > 0
    assert np.flatnonzero(theirs & (found == 0)).tolist() == [] and found.max() == 1


def test_a_hands_run_lets_a_chunks_frames_go_before_the_next_are_read(tmp_path, monkeypatch):
    """As the body's run (tests/test_pipeline.py): one chunk of decoded frames at a time. One frame of the
    previous chunk is still held here (which holder was not traced); a chunk's worth is what matters."""
    with frames_alive_at_each_chunk(monkeypatch) as alive:
        run(RunConfig(CLIP, mode="hands", end=32, chunk_size=16, progress=False, overlay=False), tmp_path)
    assert len(alive) == 2 and max(alive) <= 1, alive


def test_interrupted_hands_run_resumes_to_the_same_hands(video, tmp_path, monkeypatch):
    import jaxmocap.pipeline.hands_job as job

    _, _, whole = video
    solve, calls = job.solve_hand_chunk, []

    def solve_or_stop(*args):
        calls.append(1)
        if len(calls) == 2:
            raise KeyboardInterrupt
        return solve(*args)

    config = RunConfig(CLIP, mode="hands", end=32, chunk_size=16, progress=False, overlay=False)
    monkeypatch.setattr(job, "solve_hand_chunk", solve_or_stop)
    with pytest.raises(KeyboardInterrupt):
        run(config, tmp_path)
    assert len(list((tmp_path / ".jaxmocap_chunks").glob("chunk_*.npz"))) == 1
    monkeypatch.setattr(job, "solve_hand_chunk", solve)
    resumed = read_hands(run(config, tmp_path).motion)
    for key in ("right_valid", "right_hand_pose", "right_camera_trans", "left_valid"):
        np.testing.assert_allclose(resumed[key], whole[key], atol=1e-5)


def test_detect_hands_writes_hand_only_openpose_json(tmp_path, capsys):
    assert main(["detect", str(CLOSEUP), "--mode", "hands", "--out", str(tmp_path), "--quiet"]) == 0
    (person,) = json.loads((tmp_path / "opencv_handSrc_keypoints.json").read_text())["people"]
    assert person["pose_keypoints_2d"] == [] and len(person["hand_left_keypoints_2d"]) == 63


def test_frankmocap_hand_regressor_starts_the_fit(frankmocap, video, tmp_path, monkeypatch):
    """Random FrankMocap-format checkpoints, converted: on each hand's box the hand regressor predicts what the
    PyTorch reference network does on FrankMocap's crop of that box, the fit starts from that prediction, and
    ends on the keypoints but elsewhere than from the IK's start (the run without weights)."""
    import frankmocap_reference as ref
    import jaxmocap.pipeline.hands_job as hands_job

    regressed, fit, calls = hands_job.regressed, hands_job.fit_hands, {}

    def regressed_spy(*args):  # the real regressor, its arguments and result kept
        calls["regressed"] = args, regressed(*args)
        return calls["regressed"][1]

    def fit_spy(*args, start, **options):  # the real fit, its start kept
        calls["start"] = start
        return fit(*args, start=start, **options)

    monkeypatch.setattr(hands_job, "regressed", regressed_spy)
    monkeypatch.setattr(hands_job, "fit_hands", fit_spy)
    report = run(RunConfig(CLIP, mode="hands", weights=frankmocap[0] / "weights", end=8, overlay=False,
                           smooth=False, progress=False), tmp_path / "out")
    (_, _, table, rows, frames, side), ((wrist, fingers), ok) = calls["regressed"]
    assert side == "right" and ok.all() and calls["start"][1] is fingers
    model = smplx_jax.load_model(smplx_jax.default_model_path())
    for row, pose in zip(rows, fingers, strict=True):
        x0, y0, x1, y1 = table["box"][row]
        crop, _, _ = ref.hand_crop(frames[table["frame"][row]], (x0, y0, x1 - x0, y1 - y0))
        with torch.no_grad():
            raw = frankmocap[1](torch.from_numpy((crop / 255.0 - 0.5) / 0.5).float().permute(2, 0, 1)[None])[0]
        np.testing.assert_allclose(pose, raw[6:51].numpy().reshape(15, 3) + np.asarray(model.hand_mean[1]).reshape(
            15, 3), atol=2e-3)
    hands, without = read_hands(report.motion), video[2]
    valid = hands["right_valid"] & without["right_valid"][:8]
    assert valid.sum() >= 4
    errors = hands["right_reprojection_error_px"][valid] / box_size(hands["right_keypoints_2d"][valid])
    print("median error, share of the box", np.median(errors))
    assert np.median(errors) <= 0.3  # measured 0.19: 20 iterations from a random network's hands
    assert np.abs(hands["right_hand_pose"][valid] - without["right_hand_pose"][:8][valid]).max() > 0.1


def test_live_hands_streams_and_records_each_hand(video, tmp_path):
    """``live --mode hands`` on the close-up clip, played as fast as solved: each frame solved, its hands sent over
    UDP and recorded; the recording agrees with the offline run (within a few pixels: causal filters)."""
    from jaxmocap.live import LiveConfig, live
    from jaxmocap.live.hands import hand_step

    _, _, offline = video
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(0.5)
    report = live(LiveConfig(CLIP, mode="hands", max_frames=32, record=tmp_path, udp=receiver.getsockname(),
                             progress=False))
    messages = []
    with receiver:
        try:
            while True:
                messages.append(json.loads(receiver.recv(65536)))
        except TimeoutError:
            pass
    recorded = read_hands(tmp_path / "hands.npz")
    assert report.solved == 32 and np.array_equal(recorded["frame_index"], np.arange(32))
    assert_kept_for_the_next_process(hand_step)
    valid = recorded["right_valid"]
    assert valid.sum() >= 20 and np.median(recorded["right_reprojection_error_px"][valid]) <= 0.03 * np.median(
        box_size(recorded["right_keypoints_2d"][valid]))
    sent = [m for m in messages if m["hands"]]
    assert len(sent) >= 20 and all(m["people"] == [] and m["hands"][0]["side"] == "right" for m in sent)
    both = valid & offline["right_valid"]
    joints = {}
    for name, hands in (("live", recorded), ("offline", offline)):
        x = np.asarray(hand_meshes(smplx_jax.hand_model(MODEL, "right"), hands["right_global_orient"],
                                   hands["right_hand_pose"]).joints)
        joints[name] = hands["right_camera_scale"][:, None, None] * x[..., :2] + hands["right_camera_trans"][:, None]
    assert np.median(np.linalg.norm(joints["live"] - joints["offline"], axis=-1)[both]) < 5.0


def test_fit_recovers_the_hands_it_was_made_from():
    """Hands of known poses, wrist rotations and cameras: their joints as the world landmarks (metres, any offset)
    and projected as the keypoints; the fit finds joints within 6 mm (1 mm on average; depth is the 3D landmarks'
    alone) and pixels within 0.5 px, both sides."""
    rng = np.random.default_rng(0)
    count = 8
    flex = np.zeros((count, 15, 3), np.float32)
    flex[:, :12, 2] = rng.uniform(0.0, 1.2, (count, 12))  # index to ring fingers bent (right hand: +z)
    flex[:, 12:, 1] = rng.uniform(-0.4, 0.2, (count, 3))
    for side, sign in (("right", 1.0), ("left", -1.0)):
        pose = flex * np.array([1.0, sign, sign], np.float32)  # the left hand mirrors the right
        orient = rng.normal(0, 1.0, (count, 3)).astype(np.float32)
        truth = np.asarray(hand_meshes(smplx_jax.hand_model(MODEL, side), orient, pose).joints)
        scale, trans = rng.uniform(800, 2000, count), rng.uniform(100, 400, (count, 2))
        keypoints = np.concatenate([scale[:, None, None] * truth[..., :2] + trans[:, None], np.ones((count, 21, 1))],
                                   axis=-1)
        fit = fit_hands(MODEL, side, truth + 0.3, np.ones((count, 21)), keypoints)
        joints = np.asarray(hand_meshes(smplx_jax.hand_model(MODEL, side), fit.global_orient, fit.hand_pose).joints)
        assert fit.valid.all() and fit.reprojection_error_px.max() < 0.5
        error = np.linalg.norm(joints - truth, axis=-1)
        assert error.max() < 0.006 and error.mean() < 0.001, (side, error.max(), error.mean())


@pytest.mark.parametrize("side", ["right", "left"])
def test_a_hands_frames_are_fitted_as_one_with_their_motion(side):
    """A hand turning and flexing smoothly (60 frames/s), seen with 2 px of noise: fitted as one clip from each
    frame's own fit, its joints land nearer the truth and accelerate less (the motion term), and it still meets
    its keypoints. With the motion term cut (``fps`` 0) the joints' accelerations stay the frames' own: checked."""
    from jaxmocap.integrate.clip import HAND_BONES
    from jaxmocap.pipeline import hands_job
    from jaxmocap.pipeline.stages import lens_of

    count, fps = 40, 60.0
    rng = np.random.default_rng(1)
    time = np.arange(count) / fps
    sign = 1.0 if side == "right" else -1.0
    pose = np.zeros((count, 15, 3), np.float32)
    pose[:, :12, 2] = sign * (0.6 + 0.4 * np.sin(2 * np.pi * time[:, None] + np.arange(12)))
    orient = np.stack([np.pi + 0.3 * np.sin(2 * time), 0.4 * np.cos(3 * time), 0.5 * time], 1).astype(np.float32)
    hand = smplx_jax.hand_model(MODEL, side)
    truth = np.asarray(hand_meshes(hand, orient, pose).joints)
    scale = 1500 + 200 * np.sin(time)
    trans = np.stack([300 + 100 * time, 300 + 20 * np.sin(3 * time)], 1)
    keypoints = np.concatenate([scale[:, None, None] * truth[..., :2] + trans[:, None], np.ones((count, 21, 1))], -1)
    keypoints[..., :2] += rng.normal(0, 2.0, (count, 21, 2))
    world = truth + rng.normal(0, 0.003, truth.shape)
    own = fit_hands(MODEL, side, world, np.ones((count, 21)), keypoints.astype(np.float32))
    arrays = {name: np.asarray(getattr(own, name)) for name in hand_fit.HandFit._fields} | {
        "keypoints_2d": keypoints.astype(np.float32)}

    def joints(a):
        return np.asarray(hand_meshes(hand, a["global_orient"], a["hand_pose"]).joints)

    def acceleration(x):
        return np.linalg.norm(x[:-2] - 2 * x[1:-1] + x[2:], axis=-1).mean()

    lens = lens_of((640, 640))
    fitted = {rate: hands_job.fitted_side(MODEL, lens, rate, side, arrays, world) for rate in (fps, 0.0)}
    assert fitted[fps]["valid"].all() and len(HAND_BONES) == 20
    error = {k: np.linalg.norm(joints(a) - truth, axis=-1).mean() for k, a in (("own", arrays), *fitted.items())}
    moving = {k: acceleration(joints(a)) for k, a in (("own", arrays), *fitted.items())}
    assert error[fps] < 0.8 * error["own"], error
    assert moving[fps] < 0.6 * moving["own"] and moving[0.0] > 0.8 * moving["own"], moving
    assert np.median(fitted[fps]["reprojection_error_px"]) < 3.0


def test_hands_export_glTF_only_and_say_so(tmp_path, capsys):
    code = main(["run", str(CLOSEUP), "--mode", "hands", "--export", "bvh", "--out", str(tmp_path), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "glTF only" in err


def _with_exif_orientation(jpeg: bytes, orientation: int) -> bytes:
    """A JPEG with an EXIF APP1 segment holding only the orientation tag (as a phone writes a portrait photo)."""
    entry = b"\x12\x01\x03\x00\x01\x00\x00\x00" + bytes([orientation, 0, 0, 0])  # tag 0x0112, SHORT, 1 value
    tiff = b"II*\x00\x08\x00\x00\x00" + b"\x01\x00" + entry  # little-endian header, one IFD entry
    exif = b"Exif\x00\x00" + tiff + b"\x00\x00\x00\x00"
    return jpeg[:2] + b"\xff\xe1" + (len(exif) + 2).to_bytes(2, "big") + exif + jpeg[2:]


def test_a_phone_photo_is_read_upright(still, tmp_path):
    """A JPEG stored sideways with EXIF orientation 6 (turn 90 degrees clockwise to view) is fitted upright."""
    sideways = cv2.rotate(cv2.imread(str(CLOSEUP)), cv2.ROTATE_90_COUNTERCLOCKWISE)
    photo = tmp_path / "photo.jpg"
    photo.write_bytes(_with_exif_orientation(cv2.imencode(".jpg", sideways, [cv2.IMWRITE_JPEG_QUALITY, 95])[1]
                                             .tobytes(), 6))
    run(RunConfig(photo, mode="hands", overlay=False, progress=False), tmp_path / "out")
    hands, upright = read_hands(tmp_path / "out" / "hands.npz"), still[2]
    assert hands["image_size"].tolist() == [640, 480] and hands["left_valid"][0]
    assert np.abs(hands["left_keypoints_2d"][0, :, :2] - upright["left_keypoints_2d"][0, :, :2]).max() < 10.0


def test_the_live_hand_solve_runs_on_the_host_cpu():
    """As the body's live solve (`test_live.test_the_solve_runs_on_the_host_cpu`): the hand models it solves with
    and lens are committed to the CPU, so `hand_step` runs there beside a GPU."""
    from jaxmocap.live.hands import HandSolver
    from jaxmocap.pipeline.stages import lens_of

    solver = HandSolver(MODEL, lens_of((320, 320)))
    for leaf in jax.tree.leaves((solver.models, solver.lens)):
        assert leaf.committed and leaf.devices() == {jax.devices("cpu")[0]}
