"""A live session's recording written as it goes: columns on disk written as one .npz (`jaxmocap.columns`), the
recorders' files equal to what was added, memory that does not grow with the session (`jaxmocap.live.record`)."""

import dataclasses
import io
import shutil
import time
import tracemalloc

import jax
import numpy as np
import pytest

import smplx_jax
from conftest import programs_lowered
from jaxmocap.columns import Columns, write_npz
from jaxmocap.integrate.ground import Floor
from jaxmocap.live.causal import Solved
from jaxmocap.live.record import JOURNAL, Recorder
from jaxmocap.live.world import LiveWorld
from jaxmocap.motion import read_motion

LENS = (800.0, np.asarray([320.0, 240.0]))


@pytest.fixture(scope="module")
def model():
    return smplx_jax.load_model(smplx_jax.default_model_path())


def _recorder(folder, model, every_s=3600.0, world=None) -> Recorder:
    return Recorder(folder, model, "0" * 64, LENS, 30.0, (640, 480), "full", every_s=every_s, world=world)


def test_columns_written_as_numpy_writes_them(tmp_path):
    rng = np.random.default_rng(0)
    parts = [{"a": rng.normal(size=(n, 2, 3)).astype(np.float32), "b": rng.random(n) > 0.5,
              "c": np.arange(n, dtype=np.int64)} for n in (3, 0, 5)]
    columns = Columns(tmp_path / "journal")
    for part in parts:
        columns.append(part)
    constants = {"fps": np.asarray(30.0), "name": np.asarray("abc"), "size": np.asarray([640, 480])}
    write_npz(tmp_path / "out.npz", [columns], constants)
    expected = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]} | constants
    buffer = io.BytesIO()
    np.savez(buffer, **expected)
    with np.load(tmp_path / "out.npz") as written, np.load(io.BytesIO(buffer.getvalue())) as saved:
        assert sorted(written.files) == sorted(saved.files)
        for key in saved.files:
            assert written[key].dtype == saved[key].dtype and written[key].shape == saved[key].shape, key
            np.testing.assert_array_equal(written[key], saved[key], err_msg=key)
    with pytest.raises(ValueError, match="layout"):
        columns.append({"a": np.zeros((1, 2, 3)), "b": np.zeros(1, bool), "c": np.zeros(1, np.int64)})  # float64
    with pytest.raises(ValueError, match="lengths"):
        columns.append({k: v[:2] if k == "a" else v for k, v in parts[0].items()})


def _solved(model, rng) -> Solved:
    """A random body 3 m in front of the camera."""
    params = smplx_jax.SMPLXParams.zeros(model.num_betas, model.num_expression)
    params = jax.tree.map(lambda a: rng.normal(scale=0.1, size=a.shape).astype(np.float32), params)
    params = dataclasses.replace(params, transl=np.asarray([0.0, 0.2, 3.0], np.float32))
    return Solved(params, np.float32(250.0), rng.normal(size=2).astype(np.float32) + 300, np.bool_(True))


def test_the_recording_holds_every_frame_added_each_person_from_the_start(tmp_path, model):
    """Person 0 throughout, person 1 from frame 7 on (absent before, with the frames' own numbers and times); a
    flush between any two frames; the files equal the motion of the frames added."""
    rng = np.random.default_rng(1)
    recorder = _recorder(tmp_path, model)
    added = []
    for frame in range(12):
        people = {0: _solved(model, rng)} | ({1: _solved(model, rng)} if frame >= 7 else {})
        keypoints = {i: rng.random((67, 3)).astype(np.float32) for i in people}
        recorder.add(100 + frame, frame / 30, people, keypoints)
        added.append((people, keypoints))
        if frame in (2, 3, 8):
            recorder.flush()
    assert (tmp_path / JOURNAL).is_dir()
    written = recorder.close(60)
    assert not (tmp_path / JOURNAL).exists()
    assert sorted(p.relative_to(tmp_path).as_posix() for p in written) == [
        "motion.npz", "people/0/motion.npz", "people/1/motion.npz"]
    for person in (0, 1):
        motion = read_motion(tmp_path / "people" / str(person) / "motion.npz")
        np.testing.assert_array_equal(motion["frame_index"], np.arange(100, 112))
        np.testing.assert_allclose(motion["time_s"], np.arange(12) / 30)
        seen = np.asarray([person in people for people, _ in added])
        np.testing.assert_array_equal(motion["valid"], seen)
        for row in np.flatnonzero(seen):
            solved = added[row][0][person]
            np.testing.assert_array_equal(motion["body_pose"][row], solved.params.body_pose)
            np.testing.assert_array_equal(motion["keypoints_2d"][row], added[row][1][person])
        assert not motion["keypoints_2d"][~seen].any()
        assert float(motion["focal_length"]) == LENS[0] and str(motion["model_sha256"]) == "0" * 64
    main = read_motion(tmp_path / "motion.npz")
    np.testing.assert_array_equal(main["valid"], np.ones(12, bool))  # person 0: valid in most frames


def test_memory_holds_only_the_frames_since_the_last_flush(tmp_path, model):
    """Frames added and flushed in batches: Python's allocations after 3000 frames are those after 600 (the frames
    themselves, some 1.5 kB each, would add over 3 MB)."""
    rng = np.random.default_rng(2)
    frame = (_solved(model, rng), rng.random((67, 3)).astype(np.float32))
    recorder = _recorder(tmp_path, model)
    tracemalloc.start()
    try:
        for index in range(3000):
            solved = frame[0]._replace(params=jax.tree.map(np.copy, frame[0].params))  # each frame its own arrays
            recorder.add(index, index / 30, {0: solved}, {0: frame[1].copy()})
            if index % 150 == 149:
                recorder.flush()
            if index == 599:
                early = tracemalloc.get_traced_memory()[0]
        late = tracemalloc.get_traced_memory()[0]
    finally:
        tracemalloc.stop()
    recorder.close(60)
    assert late - early < 1_000_000, (early, late)
    assert len(read_motion(tmp_path / "motion.npz")["valid"]) == 3000


def test_a_failed_write_is_raised_by_the_next_frame_and_at_close(tmp_path, model):
    """The writing thread's error (here: its journal gone) stops the session at its next frame and again at its
    end; the files keep what was written before."""
    recorder = _recorder(tmp_path, model, every_s=0.05)
    frame = ({0: _solved(model, np.random.default_rng(3))}, {0: np.zeros((67, 3), np.float32)})
    recorder.add(0, 0.0, *frame)
    recorder.flush()
    shutil.rmtree(tmp_path / JOURNAL)
    with pytest.raises(FileNotFoundError):
        for index in range(1, 100):  # until the thread's next flush fails
            recorder.add(index, index / 30, *frame)
            time.sleep(0.05)
    with pytest.raises(FileNotFoundError):
        recorder.close(60)
    assert len(read_motion(tmp_path / "motion.npz")["valid"]) == 1


def test_a_flush_compiles_nothing_once_warmed_up(tmp_path, model):
    """Flushes of any number of frames, the world keys of the whole recording included (its floor found), run only
    programs `Recorder.warm_up` compiled before the session: one compiled by the writing thread takes the solve's
    cores for seconds (each flush's world keys were one program for each length of the recording)."""
    world = LiveWorld(model, LENS, 640)
    world.floor = Floor(np.asarray([0.0, -1.0, 0.0]), 1.0)  # 1 m below the camera (y down)
    world.camera_from_world = np.asarray([[1, 0, 0, 0], [0, -1, 0, 1], [0, 0, -1, 0], [0, 0, 0, 1]], np.float64)
    recorder = _recorder(tmp_path, model, world=world)
    recorder.warm_up()
    rng, added = np.random.default_rng(4), 0
    with programs_lowered() as lowered:
        for count in (3, 20, 50, 100):
            for _ in range(count):
                recorder.add(added, added / 30, {0: _solved(model, rng)}, {0: rng.random((67, 3)).astype(np.float32)})
                added += 1
            recorder.flush()
    assert lowered == []
    recorder.close(60)
    motion = read_motion(tmp_path / "motion.npz")
    assert motion["world_transl"].shape == (added, 3) and np.isfinite(motion["world_global_orient"]).all()
