"""`jaxmocap live`: the hand-offs, the filter, the web page and the stream on their own; then the causal path on
the bundled clip played as live (every frame, or in real time and slowed down on purpose), the stream parsed
back, agreement with the offline run, and the command's exits (Ctrl-C, a camera that cannot be opened)."""

import dataclasses
import ipaddress
import json
import os
import signal
import socket
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import smplx_jax
from bench import accuracy
from bench import live as live_bench
from conftest import assert_kept_for_the_next_process, assert_one_body, cli_as_from_a_terminal
from jaxmocap.errors import InputError
from jaxmocap.frame_source import MediaError
from jaxmocap.integrate import synthetic
from jaxmocap.integrate.clip import FOOT_JOINTS, points_3d
from jaxmocap.integrate.inverse_kinematics import BLAZEPOSE_TO_SMPLX
from jaxmocap.integrate.keypoints import keypoint_model, keypoints_cm
from jaxmocap.integrate.motion_arrays import body_joints
from jaxmocap.live import LiveConfig, LiveSettings, causal, live, params_from_message
from jaxmocap.live.causal import CausalSolver
from jaxmocap.live.mailbox import Closed, Mailbox
from jaxmocap.live.record import FLUSH_SECONDS
from jaxmocap.live.session import Session
from jaxmocap.live.source import LiveSource
from jaxmocap.live.stream import frame_message, parse_address, person_message
from jaxmocap.live.viewer import Viewer
from jaxmocap.motion import WORLD_SHAPES, motion_params, read_motion
from jaxmocap.pipeline import RunConfig, run
from jaxmocap.pipeline.observe import Observations, _no_one
from jaxmocap.pipeline.stages import lens_of

CLIP = Path(__file__).resolve().parents[1] / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"


# -- the parts ----------------------------------------------------------------------------------------------------
def test_mailbox_keeps_only_the_newest_and_counts_the_rest():
    box = Mailbox()
    for k in range(5):
        box.put(k)
    assert box.get(timeout=1) == 4 and box.dropped == 4
    with pytest.raises(TimeoutError):
        box.get(timeout=0.01)
    box.put("last")
    box.close()
    assert box.get() == "last"
    with pytest.raises(Closed):
        box.get()


def test_mailbox_waits_when_lossless():
    box, taken = Mailbox(), []

    def take():
        for _ in range(20):
            taken.append(box.get(timeout=5))

    reader = threading.Thread(target=take)
    reader.start()
    for k in range(20):
        box.put(k, wait=True)
    reader.join()
    assert taken == list(range(20)) and box.dropped == 0


class _Counted:
    """A capture whose frames converted to images (`retrieve`, `read`) are counted."""

    def __init__(self, capture):
        self.capture, self.converted = capture, 0

    def __getattr__(self, name):
        return getattr(self.capture, name)

    def retrieve(self):
        self.converted += 1
        return self.capture.retrieve()

    def read(self):
        self.converted += 1
        return self.capture.read()


def test_a_file_played_as_live_drops_what_a_slow_reader_misses_and_converts_only_what_it_takes():
    source = LiveSource(CLIP, realtime=True)
    source.capture = counted = _Counted(source.capture)
    source.start()
    taken = []
    try:
        while True:
            frame = source.frames.get(timeout=5)
            assert frame.image.shape == (1920, 1080, 3)
            taken.append(frame.index)
            time.sleep(0.05)  # three frames' time at 60 fps
    except Closed:
        pass
    assert source.read == 100 and len(taken) + source.dropped == 100
    assert 20 <= len(taken) <= 45 and taken == sorted(taken) and taken[-1] >= 97
    assert counted.converted == len(taken) - 1  # the first frame was read on opening


def test_udp_messages_parse_back_into_params():
    params = smplx_jax.SMPLXParams.zeros(10, 10).replace(
        body_pose=jnp.asarray(np.random.default_rng(1).normal(0, 0.3, (21, 3)), jnp.float32))
    keypoints = np.random.default_rng(2).uniform(0, 1000, (67, 3))
    message = json.loads(frame_message(7, 0.125, [person_message(3, params, 500.0, [10.0, 20.0], keypoints)]))
    assert message["frame"] == 7 and message["time"] == 0.125 and message["people"][0]["id"] == 3
    back = params_from_message(message["people"][0])
    for a, b in zip(jax.tree.leaves(back), jax.tree.leaves(params)):
        np.testing.assert_allclose(a, b, atol=1e-5)
    assert parse_address(":9000") == ("127.0.0.1", 9000)
    with pytest.raises(ValueError, match="HOST:PORT"):
        parse_address("localhost")


def _get(port, path):
    try:
        with urllib.request.urlopen(f"http://127.0.0.1:{port}{path}", timeout=5) as reply:
            return reply.status, reply.headers["Content-Type"], reply.read()
    except urllib.error.HTTPError as err:
        return err.code, None, b""


def test_web_page_serves_its_page_and_stream_and_nothing_else():
    viewer = Viewer("127.0.0.1", 0)
    try:
        status, kind, body = _get(viewer.port, "/")
        assert status == 200 and kind.startswith("text/html") and b"/stream.mjpg" in body
        viewer.publish(b"\xff\xd8jpeg\xff\xd9", {"fps": 20.0, "latency_ms": 50.0, "dropped": 1, "people": 1})
        assert json.loads(_get(viewer.port, "/stats.json")[2])["fps"] == 20.0
        for path in ("/../../etc/passwd", "/etc/passwd", "/%2e%2e/%2e%2e/etc/passwd", "/stream.mjpg/../x",
                     "/jaxmocap/live/viewer.py", "//etc/passwd"):
            assert _get(viewer.port, path)[0] == 404, path
        with socket.create_connection(("127.0.0.1", viewer.port)) as raw:  # a path urllib would normalise
            raw.sendall(f"GET /../../etc/passwd HTTP/1.0\r\nHost: localhost:{viewer.port}\r\n\r\n".encode())
            assert raw.recv(100).startswith(b"HTTP/1.0 404")
        with urllib.request.urlopen(f"http://127.0.0.1:{viewer.port}/stream.mjpg", timeout=5) as stream:
            assert "multipart/x-mixed-replace" in stream.headers["Content-Type"]
            threading.Timer(0.2, viewer.publish, (b"\xff\xd8second\xff\xd9",)).start()
            assert stream.readline().startswith(b"--") and b"image/jpeg" in stream.readline()
    finally:
        viewer.close()


def _raw_get(port: int, path: str, host: str | None) -> tuple[int, bytes]:
    """A GET sent to 127.0.0.1 with ``Host: host`` (None: no Host header): the status and all bytes received
    within a second."""
    with socket.create_connection(("127.0.0.1", port), timeout=1.0) as raw:
        raw.sendall(f"GET {path} HTTP/1.1\r\n".encode() + (f"Host: {host}\r\n".encode() if host else b"")
                    + b"Connection: close\r\n\r\n")
        received = b""
        try:
            while chunk := raw.recv(65536):
                received += chunk
        except TimeoutError:
            pass
    return int(received.split(b" ", 2)[1]), received


def test_the_page_answers_only_requests_that_name_it():
    """DNS rebinding: a page elsewhere that rebinds its name to 127.0.0.1 sends its own name as ``Host``. Such a
    request (or one without ``Host``) gets 403 and no body on every path, the stream's frame never sent; the
    names of the loopback address with the page's port are served."""
    viewer = Viewer("127.0.0.1", 0)
    try:
        viewer.publish(b"\xff\xd8secret-frame\xff\xd9", {"fps": 20.0})
        for path in ("/", "/stats.json", "/stream.mjpg"):
            for host in (f"attacker.example:{viewer.port}", "attacker.example", f"127.0.0.1:{viewer.port + 1}",
                         None):
                status, received = _raw_get(viewer.port, path, host)
                assert status == 403 and received.endswith(b"\r\n\r\n") and b"secret" not in received, (path, host)
        for host in (f"127.0.0.1:{viewer.port}", f"localhost:{viewer.port}", f"[::1]:{viewer.port}"):
            assert _raw_get(viewer.port, "/stats.json", host)[0] == 200, host
        assert viewer.url == f"http://127.0.0.1:{viewer.port}/"
    finally:
        viewer.close()


def test_a_page_on_the_network_needs_its_token():
    """Listening on every address (``--host 0.0.0.0``; requests here sent to 127.0.0.1 only): without the token
    printed in the page's URL, or with another, 403; with it the page, its stream and rates, the page's own
    links carrying it."""
    viewer = Viewer("0.0.0.0", 0)
    try:
        viewer.publish(b"\xff\xd8secret-frame\xff\xd9", {"fps": 20.0})
        token = viewer.url.split("?token=")[1]
        assert len(token) >= 16 and viewer.url.startswith(f"http://127.0.0.1:{viewer.port}/?token=")
        host = f"192.168.1.20:{viewer.port}"  # a name the page cannot know
        for path in ("/", "/stats.json", "/stream.mjpg"):
            for query in ("", "?token=", f"?token={token[:-1]}x", f"?other={token}"):
                status, received = _raw_get(viewer.port, path + query, host)
                assert status == 403 and b"secret" not in received, (path, query)
        status, page = _raw_get(viewer.port, f"/?token={token}", host)
        assert status == 200 and f"/stream.mjpg?token={token}".encode() in page
        assert _raw_get(viewer.port, f"/stats.json?token={token}", host)[0] == 200
        assert b"secret-frame" in _raw_get(viewer.port, f"/stream.mjpg?token={token}", host)[1]
    finally:
        viewer.close()


def test_the_page_serves_a_bounded_number_of_streams():
    """Each stream holds a thread: beyond ``max_viewers`` at once, 503; a stream that goes frees its place."""
    viewer = Viewer("127.0.0.1", 0, max_viewers=2)
    host = f"127.0.0.1:{viewer.port}"
    watching = [socket.create_connection(("127.0.0.1", viewer.port)) for _ in range(2)]
    try:
        for raw in watching:
            raw.sendall(f"GET /stream.mjpg HTTP/1.1\r\nHost: {host}\r\n\r\n".encode())
            assert raw.recv(100).startswith(b"HTTP/1.0 200")
        assert _raw_get(viewer.port, "/stream.mjpg", host)[0] == 503
        assert _raw_get(viewer.port, "/", host)[0] == 200  # the page itself is not a stream
        watching.pop().close()  # its place is free once a frame fails to reach it
        deadline, status = time.monotonic() + 10, 503
        while status == 503 and time.monotonic() < deadline:
            viewer.publish(b"\xff\xd8frame\xff\xd9" * 20_000)
            status = _raw_get(viewer.port, "/stream.mjpg", host)[0]
        assert status == 200
    finally:
        for raw in watching:
            raw.close()
        viewer.close()


def test_a_frame_is_wanted_only_while_a_viewer_waits_for_one():
    """The session draws only when `Viewer.wanted`: not before anyone watches, while a viewer waits for its next
    frame, and no longer once it has gone (found at the first frames that fail to reach it)."""
    viewer = Viewer("127.0.0.1", 0, timeout=1.0)
    host = f"127.0.0.1:{viewer.port}"

    def until(condition, seconds=10.0, publish=False):
        deadline = time.monotonic() + seconds
        while not condition():
            assert time.monotonic() < deadline
            if publish:
                viewer.publish(b"\xff\xd8frame\xff\xd9" * 20_000)
            time.sleep(0.02)

    try:
        assert not viewer.wanted()
        watching = socket.create_connection(("127.0.0.1", viewer.port))
        watching.sendall(f"GET /stream.mjpg HTTP/1.1\r\nHost: {host}\r\n\r\n".encode())
        assert watching.recv(100).startswith(b"HTTP/1.0 200")
        until(viewer.wanted)
        watching.close()
        until(lambda: not viewer.wanted(), publish=True)
        viewer.publish(b"\xff\xd8frame\xff\xd9")
        time.sleep(1.5)  # the stream's wait times out and is not taken again
        assert not viewer.wanted()
    finally:
        viewer.close()


def test_a_viewer_that_stops_reading_never_stalls_publishing():
    viewer = Viewer("127.0.0.1", 0, timeout=2.0)
    stalled = socket.create_connection(("127.0.0.1", viewer.port))
    stalled.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
    stalled.sendall(f"GET /stream.mjpg HTTP/1.1\r\nHost: 127.0.0.1:{viewer.port}\r\n\r\n".encode())  # never reads
    try:
        frame = bytes(500_000)
        start = time.perf_counter()
        for _ in range(200):  # 100 MB: far beyond any socket buffer
            viewer.publish(frame)
            time.sleep(0.001)
        assert time.perf_counter() - start < 2.0
        assert _get(viewer.port, "/")[0] == 200  # and others are still served
    finally:
        stalled.close()
        viewer.close()


# -- the causal path on the clip ------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def played(tmp_path_factory):
    """The clip played twice as fast as it is solved (every frame), recorded and streamed over UDP, its page served
    (nobody watching): long enough for the floor of its first second to be found while it plays."""
    out = tmp_path_factory.mktemp("live")
    receiver = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    receiver.bind(("127.0.0.1", 0))
    receiver.settimeout(0.2)
    messages, done = [], threading.Event()

    def receive():
        while not done.is_set():
            try:
                messages.append(json.loads(receiver.recv(65536)))
            except TimeoutError:
                continue

    thread = threading.Thread(target=receive)
    thread.start()
    report = live(LiveConfig(CLIP, record=out, udp=receiver.getsockname(), serve=0, progress=False, loops=2))
    time.sleep(0.3)
    done.set()
    thread.join()
    receiver.close()
    return report, read_motion(out / "motion.npz"), messages


def test_every_frame_is_solved_when_played_as_fast_as_solved(played):
    report, motion, _ = played
    assert report.stopped == "end of stream" and report.read == report.solved == 200 and report.dropped == 0
    assert {stage: len(ms) for stage, ms in report.stage_ms.items()} == dict.fromkeys(
        ("detect", "fit", "world", "output"), 200)  # each stage timed on each frame (nobody watching: nothing drawn)
    assert all(np.all(ms > 0) for ms in report.stage_ms.values())
    assert motion["valid"].sum() >= 196 and np.array_equal(motion["frame_index"], np.arange(200))
    assert np.median(motion["reprojection_error_px"][motion["valid"]]) < 15.0
    assert_kept_for_the_next_process(causal.step)


def test_the_shape_settles_in_the_first_second_then_stays(played):
    """The clip is 60 frames/s: after 60 frames of the person, one shape."""
    _, motion, _ = played
    valid = np.flatnonzero(motion["valid"])
    assert np.all(motion["betas"][valid[61:]] == motion["betas"][valid[61]])
    assert motion["betas"][valid[:61]].std(0).max() > 0.0  # it was settling
    assert_one_body(motion, slice(61, None))


def test_the_stream_carries_the_recorded_bodies(played):
    _, motion, messages = played
    assert len(messages) >= 190  # UDP on this machine's loopback: nothing lost in practice
    for message in messages[::10]:
        row, person = message["frame"], message["people"][0]
        recorded = jax.tree.map(lambda a: a[0], motion_params(motion, 10, [row]))
        for a, b in zip(jax.tree.leaves(params_from_message(person)), jax.tree.leaves(recorded)):
            np.testing.assert_allclose(a, b, atol=2e-5)
        np.testing.assert_allclose(person["keypoints_2d"], motion["keypoints_2d"][row], atol=0.01)


def test_the_stream_and_the_recording_stand_on_the_sessions_floor(played):
    """Once the floor of the session's first second with the person (`world.FLOOR_SECONDS`) is found, each message
    carries the world keys, the recording's rows the same (contacts: the recording's about each frame, the stream's
    from the frames up to it); the floor is the room's."""
    _, motion, messages = played
    assert set(WORLD_SHAPES) <= set(motion)
    with_world = [m for m in messages if "floor" in m]
    first = min(m["frame"] for m in with_world)
    assert first >= 60 and all(m["frame"] < first for m in messages if "floor" not in m)
    # the room's up seen from this camera (its calibration), through the default lens (some 3 degrees off)
    assert np.degrees(np.arccos(motion["floor"][:3] @ accuracy.room_up("cam01"))) < 4.0
    agree = []
    for message in with_world:
        row, person = message["frame"], message["people"][0]
        np.testing.assert_allclose(message["floor"], motion["floor"], atol=1e-5)
        np.testing.assert_allclose(person["world_global_orient"], motion["world_global_orient"][row], atol=1e-4)
        np.testing.assert_allclose(person["world_transl"], motion["world_transl"][row], atol=1e-4)
        agree.append(np.mean(np.asarray(person["contact"]) == motion["contact"][row]))
    assert np.mean(agree) > 0.8
    world = motion_params(motion | {"global_orient": motion["world_global_orient"],
                                    "transl": motion["world_transl"]}, 10)
    soles = body_joints(smplx_jax.load_model(smplx_jax.default_model_path()), world)[:, FOOT_JOINTS, 1]
    assert np.abs(np.median(soles[motion["contact"]])) < 0.05  # the soles' joints a few centimetres above y = 0


def test_the_solve_runs_on_the_host_cpu():
    """One frame's solve is latency-bound (a few hundred small operations): beside a GPU it stays on the CPU
    (`causal.host`; on an H200 machine 12 ms there against 36 ms on the GPU), its inputs and state committed there
    (uncommitted arrays would follow JAX's default device)."""
    solver = CausalSolver(smplx_jax.load_model(smplx_jax.default_model_path()), lens_of((1080, 1920)))
    nobody = Observations(**_no_one(1))
    solver({0: nobody}, 0.0)
    state, _ = solver.people[0]
    for leaf in jax.tree.leaves((solver.models, solver.lens, state)):
        assert leaf.committed and leaf.devices() == {jax.devices("cpu")[0]}


def synthetic_observations(model, frames: int, fps: float, lens):
    """`synthetic.make_clip`'s body as the detector would give it: OpenPose keypoints with 2 px of noise, BlazePose's
    world landmarks (the body's joints about its hips, 1 cm of noise), no hands."""
    clip = synthetic.make_clip(model, frames, seed=1, focal_length=lens[0], principal_point=lens[1], fps=fps)
    rng = np.random.default_rng(1)
    keypoints = clip.keypoints.astype(np.float32)
    keypoints[..., :2] += rng.normal(scale=2.0, size=keypoints[..., :2].shape)
    keypoints[:, 25:, 2] = 0.0
    betas = jnp.asarray(clip.betas, jnp.float32)
    landmarks, joints = list(BLAZEPOSE_TO_SMPLX), list(BLAZEPOSE_TO_SMPLX.values())
    km = keypoint_model(model, joints)
    world = np.zeros((frames, 33, 4), np.float32)
    points = np.asarray(jax.vmap(lambda p: keypoints_cm(km, p, betas).T)(jnp.asarray(clip.pose, jnp.float32)))
    world[:, landmarks, :3] = points + rng.normal(scale=0.01, size=points.shape)
    world[..., :3] -= world[:, [23, 24], :3].mean(1, keepdims=True)
    world[:, landmarks, 3] = 1.0
    nothing = _no_one(1)
    observations = [Observations(keypoints[t:t + 1], world[t:t + 1], nothing["hands_world"], nothing["hands_conf"],
                                 nothing["body_box"], nothing["hand_boxes"], np.ones(1, bool)) for t in range(frames)]
    return observations


def test_each_frame_is_solved_with_the_ones_before_it():
    """Live solves each frame in a window with the frames before it (the clip fit's motion term, in m/s^2 at the
    frame rate): on a synthetic clip its 3D keypoints' accelerations are well below those of the same frames
    solved without the motion term, and both lie on the keypoints within their 2 px of noise."""
    model = smplx_jax.load_model(smplx_jax.default_model_path())
    fps, lens = 30.0, lens_of((1920, 1080))
    observations = synthetic_observations(model, 30, fps, lens)
    keypoints = np.concatenate([obs.keypoints for obs in observations])
    alone = dataclasses.replace(LiveSettings().fit, acceleration_sigma=1e9, angular_acceleration_sigma=1e9)
    results = {}
    for name, settings in (("window", LiveSettings()), ("alone", LiveSettings(fit=alone))):
        solver = CausalSolver(model, lens, settings)
        solved = [solver({0: obs}, t / fps)[0] for t, obs in enumerate(observations)]
        params = jax.tree.map(lambda *a: jnp.asarray(np.stack(a)), *[s.params for s in solved])
        x = np.asarray(jax.vmap(lambda p: points_3d(solver.models.openpose, p.full_pose(), p.betas, p.transl))(
            params))[:, :25]
        pixels = lens[0] * x[..., :2] / x[..., 2:] + lens[1]
        results[name] = (np.median(np.linalg.norm(x[:-2] - 2 * x[1:-1] + x[2:], axis=-1)) * fps**2,
                         np.median(np.linalg.norm(pixels - keypoints[:, :25, :2], axis=-1)))
    (jitter, pixels), (jitter_alone, pixels_alone) = results["window"], results["alone"]
    assert jitter < 0.75 * jitter_alone, results
    assert pixels < 2.5 and pixels_alone < 2.5, results


def test_live_agrees_with_the_offline_run(played, tmp_path):
    """The offline run's frames 20-27 (the shapes `test_pipeline` compiles) against the live ones."""
    _, motion, _ = played
    run(RunConfig(CLIP, start=20, end=28, chunk_size=4, overlay=False, progress=False, landmarks="full"), tmp_path)
    model = smplx_jax.load_model(smplx_jax.default_model_path())
    error, frames = live_bench.agreement_mm(model, motion, read_motion(tmp_path / "motion.npz"), first_frame=20)
    assert frames == 8 and error <= 30.0, error


def test_frames_are_dropped_not_queued_when_the_solve_is_slowed(monkeypatch):
    """Each solved frame waits at most for the detection and the solve in progress, then its own: its latency is
    within two detections' and two solves' time, and the slower of the two stages is never idle while frames come,
    so the solver takes about as many frames as the stream's 1.67 s hold of that stage's steps (all measured in the
    same run, so that a machine busy with other work slows them alike: there, detection may be the slower)."""
    solve, observe, solves_ms, detections_ms = CausalSolver.__call__, Session._observe, [], []

    def timed(function, times, pause=0.0):
        def wrapper(*args):
            begin = time.perf_counter()
            time.sleep(pause)
            out = function(*args)
            times.append(1000 * (time.perf_counter() - begin))
            return out
        return wrapper

    monkeypatch.setattr(CausalSolver, "__call__", timed(solve, solves_ms, pause=0.06))
    monkeypatch.setattr(Session, "_observe", timed(observe, detections_ms))
    report = live(LiveConfig(CLIP, realtime=True, progress=False))
    assert report.read == 100 and report.solved + report.dropped == 100
    step_ms = max(np.mean(solves_ms), np.mean(detections_ms))
    assert 0.6 * 1000 * 100 / 60 / step_ms <= report.solved <= 40, (report.summary(), np.mean(solves_ms),
                                                                      np.mean(detections_ms))
    limit = 1.25 * 2 * (np.percentile(detections_ms, 95) + np.percentile(solves_ms, 95))
    assert np.percentile(report.latency_ms, 95) <= limit, (report.summary(), limit)


# -- the command ------------------------------------------------------------------------------------------------------
def _capturing(process: subprocess.Popen) -> str:
    """The live command's start line (``live: capturing ...``), once its stderr says so; fails if it ends first."""
    line = ""
    while "capturing" not in line:
        line = process.stderr.readline()
        assert line or process.poll() is None, process.stderr.read()
    return line


def test_ctrl_c_stops_cleanly_with_the_page_served_and_the_recording_written(tmp_path):
    command = cli_as_from_a_terminal("live", str(CLIP), "--realtime", "--loop", "0", "--serve", "0", "--record",
                                     str(tmp_path), "--quiet", python_options=("-X", "faulthandler"))
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = _capturing(process)
        port = int(line.rsplit(":", 1)[1].split("/")[0])
        assert "http://127.0.0.1:" in line and _listening_on(port) == ["127.0.0.1"]  # this machine only
        deadline = time.monotonic() + 120  # until 10 frames are solved (the page's stats, once a second)
        while json.loads(_get(port, "/stats.json")[2])["solved"] < 10:
            assert time.monotonic() < deadline and process.poll() is None, "fewer than 10 frames solved in 120 s"
            time.sleep(0.5)
        status, kind, _ = _get(port, "/")
        assert status == 200 and _get(port, "/../etc/passwd")[0] == 404
        process.send_signal(signal.SIGINT)
        try:
            out, err = process.communicate(timeout=180)
        except subprocess.TimeoutExpired:  # every thread's stack, for the report
            process.send_signal(signal.SIGABRT)
            out, err = process.communicate(timeout=30)
            pytest.fail(f"no exit 180 s after Ctrl-C:\n{err[-6000:]}")
    finally:
        process.kill()
    assert process.returncode == 0, err
    assert out.startswith("interrupted: ") and "frames/s" in out
    assert read_motion(tmp_path / "motion.npz")["valid"].sum() >= 10


def _rss_mb(pid: int) -> float:
    """A process's resident memory (MB), from /proc."""
    status = Path(f"/proc/{pid}/status").read_text()
    return int(status.split("VmRSS:")[1].split()[0]) / 1024


def test_a_recording_killed_keeps_all_but_its_last_seconds_and_its_memory_stays_flat(tmp_path):
    """``--record`` of a file looping in real time, killed outright (SIGKILL) 45 s into capture: motion.npz holds
    every frame up to the last flush (`FLUSH_SECONDS` before the kill at most, and the moments a frame takes to be
    solved and written); the process's resident memory grows by 50 MB at most between 15 s and 45 s."""
    command = cli_as_from_a_terminal("live", str(CLIP), "--realtime", "--loop", "0", "--record", str(tmp_path),
                                     "--quiet")
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _capturing(process)
        started = time.monotonic()
        time.sleep(15)
        early = _rss_mb(process.pid)
        time.sleep(30)
        late, seconds = _rss_mb(process.pid), time.monotonic() - started
        process.kill()
        process.wait(timeout=30)
    finally:
        process.kill()
    motion = read_motion(tmp_path / "motion.npz")
    assert motion["time_s"][-1] >= seconds - FLUSH_SECONDS - 2.0, (motion["time_s"][-1], seconds)
    assert motion["valid"].mean() > 0.9
    assert late - early <= 50, (early, late)


def test_a_stalled_stream_stops_within_seconds_of_ctrl_c(tmp_path):
    """A network source that stops sending, its connection left open (here an MJPEG stream of grey frames that
    stalls; without a timeout its read never returned), cannot keep the session alive: Ctrl-C ends it within 5 s,
    cleanly (no thread left in a read as the process exits: that crashed it)."""
    import cv2

    image = cv2.imencode(".jpg", np.full((240, 320, 3), 90, np.uint8))[1].tobytes()
    stream, sending = Viewer("127.0.0.1", 0), threading.Event()
    sending.set()

    def send():
        while not stream.closed:
            if sending.is_set():
                stream.publish(image)
            time.sleep(1 / 30)

    threading.Thread(target=send, daemon=True).start()
    command = cli_as_from_a_terminal("live", f"http://127.0.0.1:{stream.port}/stream.mjpg", "--mode", "hands",
                                     "--record", str(tmp_path), "--quiet")
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _capturing(process)
        time.sleep(1.0)
        sending.clear()  # the stream stalls: the source's read blocks (until its timeout, 3 s)
        time.sleep(1.0)
        asked = time.monotonic()
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=60)
        seconds = time.monotonic() - asked
    finally:
        process.kill()
        stream.close()
    assert process.returncode == 0 and out.startswith("interrupted: "), err
    assert seconds < 5.0 and (tmp_path / "hands.npz").is_file(), seconds


def test_stopping_is_sheltered_from_a_second_ctrl_c_or_sigterm():
    """While a session stops (its recording written), Ctrl-C and SIGTERM do nothing; the handlers are back after.
    (The test's handlers fail it if a signal reaches them inside.)"""
    from jaxmocap.live.session import _sheltered

    assert threading.current_thread() is threading.main_thread()  # where signals arrive

    def reached_the_test(signum, frame):
        raise AssertionError(f"signal {signum} reached the test's handler inside the shelter")

    previous = {s: signal.signal(s, reached_the_test) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with _sheltered():
            for s in previous:
                os.kill(os.getpid(), s)
            time.sleep(0.05)  # (handlers run in the main thread between bytecodes)
        assert all(signal.getsignal(s) is reached_the_test for s in previous)
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)


def _listening_on(port: int) -> list[str]:
    """The IPv4 and IPv6 addresses a TCP socket of this machine listens on at ``port`` (Linux's /proc/net)."""
    addresses = []
    for table in ("tcp", "tcp6"):
        for row in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            local, state = row.split()[1], row.split()[3]
            address, hex_port = local.split(":")
            if state == "0A" and int(hex_port, 16) == port:  # LISTEN
                raw = bytes.fromhex(address)
                words = b"".join(raw[k:k + 4][::-1] for k in range(0, len(raw), 4))  # 32-bit words, little-endian
                addresses.append(str(ipaddress.ip_address(words)))
    return addresses


def test_bad_inputs_are_named_before_anything_runs():
    with pytest.raises(MediaError, match="missing.mp4 does not exist"):
        live(LiveConfig("missing.mp4"))
    with pytest.raises(InputError, match="bad loops"):
        LiveConfig(CLIP, loops=-1)
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        with pytest.raises(InputError, match="--serve: cannot listen on 127.0.0.1"):
            live(LiveConfig(CLIP, serve=busy.getsockname()[1]))
    with pytest.raises(OSError, match="--udp: cannot resolve no-such-host.invalid"):
        live(LiveConfig(CLIP, udp=("no-such-host.invalid", 9000)))


def test_a_camera_that_cannot_be_opened_is_one_clear_line():
    result = subprocess.run([sys.executable, "-m", "jaxmocap.cli", "live", "7"], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 2
    assert result.stderr.strip().splitlines()[-1] == \
        "jaxmocap live: error: cannot open webcam 7 (no camera with that index, or it is busy)"
