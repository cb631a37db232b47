"""The command line: exit codes, one-line errors, and the files it writes."""

import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import pytest
import smplx
import torch

import smplx_jax
from jaxmocap.cli import main


def test_model_command_writes_a_file_smplx_loads(tmp_path, capsys):
    out = tmp_path / "models" / "smplx" / "SMPLX_NEUTRAL.npz"
    assert main(["model", "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    body = smplx.create(str(tmp_path / "models"), model_type="smplx", use_pca=False, flat_hand_mean=True)
    with torch.no_grad():
        joints = body(body_pose=torch.full((1, 63), 0.1)).joints
    assert joints.shape == (1, 127, 3) and torch.isfinite(joints).all()
    assert smplx_jax.load_model(out).num_vertices == 10475


def test_model_render_writes_the_body_model_sheets(tmp_path, capsys):
    out = tmp_path / "SMPLX_NEUTRAL.npz"
    assert main(["model", "--out", str(out), "--render", str(tmp_path / "renders")]) == 0
    image = cv2.imread(str(tmp_path / "renders" / "body_model.png"))
    assert image is not None and image.shape == (1280, 960, 3)
    # the figure is drawn: plenty of non-white pixels in each of the four views
    for row in (image[:640], image[640:]):
        for view in (row[:, :480], row[:, 480:]):
            assert (view.min(axis=2) < 200).mean() > 0.03
    printed = capsys.readouterr().out
    for name, shape in (("body_model", (1280, 960, 3)), ("body_model_face", (450, 1800, 3)),
                        ("body_model_hand", (450, 1800, 3))):
        assert str(tmp_path / "renders" / f"{name}.png") in printed
        assert cv2.imread(str(tmp_path / "renders" / f"{name}.png")).shape == shape


def test_bad_model_path_is_one_line_and_nonzero(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    proc = subprocess.run([sys.executable, "-m", "jaxmocap.cli", "model", "--out", str(blocker / "x.npz")],
                          capture_output=True, text=True)
    assert proc.returncode != 0
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr
    assert proc.stderr.startswith("jaxmocap model: error:")


def test_unknown_benchmark_is_an_error(capsys):
    assert main(["bench", "--only", "nope"]) == 2
    assert "unknown benchmark(s) nope" in capsys.readouterr().err


def test_detect_on_missing_input_is_an_error(tmp_path, capsys):
    assert main(["detect", str(tmp_path / "missing.mp4"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "missing.mp4" in err


_CACHED_JIT = """
import jax, jax.numpy as jnp
from jaxmocap.cli import use_compilation_cache
events = []
jax.monitoring.register_event_listener(lambda name, **kwargs: events.append(name))
use_compilation_cache()  # keeps even this tiny program
jax.jit(lambda x: jnp.sin(x) * 2)(1.0)
print("hit" if "/jax/compilation_cache/cache_hits" in events else "miss")
"""


def test_compiled_programs_are_kept_on_disk_for_the_next_run(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"} | {"JAXMOCAP_CACHE": str(tmp_path)}
    runs = [subprocess.run([sys.executable, "-c", _CACHED_JIT], env=env, capture_output=True, text=True, check=True)
            for _ in range(2)]
    assert [r.stdout.strip() for r in runs] == ["miss", "hit"]
    assert not any("compilation cache" in r.stderr for r in runs), runs[1].stderr  # e.g. filelock missing
    assert any(f.name.endswith("-cache") for f in (tmp_path / "xla").iterdir())


def test_an_option_abbreviated_or_mistyped_is_an_error(capsys):
    """``--max-hand`` is not taken for ``--max-hands`` (nor was ``--mode`` for ``--model`` before ``--mode`` came):
    argparse's abbreviations are off in every command."""
    with pytest.raises(SystemExit) as stop:
        main(["run", "x.jpg", "--max-hand", "3"])
    assert stop.value.code == 2 and "unrecognized arguments: --max-hand 3" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["live", "0", "--seve", "8080"])
    parsers = [Path(__file__).parents[1] / d for d in ("jaxmocap", "bench", "train")]
    calls = [line for folder in parsers for path in folder.rglob("*.py") for line in path.read_text().splitlines()
             if "ArgumentParser(" in line]
    assert calls and all("allow_abbrev=False" in line for line in calls), calls


@pytest.mark.parametrize("args, message", [
    (["run", "--mode", "hands", "--keypoints", "k"], "--mode hands does not take --keypoints"),
    (["run", "--mode", "hands", "--weights", "w", "--integration", "copy-paste"],
     "--mode hands does not take --integration copy-paste"),
    (["run", "--mode", "hands", "--weights", "w", "--hand-boxes", "body"], "--mode hands does not take --hand-boxes"),
    (["run", "--mode", "body", "--weights", "w", "--hand-boxes", "body"], "--mode body does not take --hand-boxes"),
    (["run", "--max-hands", "0"], "max-hands must be positive"),
    (["detect", "--mode", "hands", "--no-hands"], "--no-hands (--mode body) cannot go with --mode hands"),
    (["detect", "--mode", "hands", "--max-hands", "0"], "--max-hands must be positive"),
    (["live", "--mode", "hands", "--max-hands", "0"], "bad max_hands 0"),
])
def test_modes_refuse_what_they_cannot_take(tmp_path, capsys, args, message):
    """Refused before anything is read: the input need not exist."""
    command, *options = args
    assert main([command, str(tmp_path / "missing.mp4"), "--out", str(tmp_path / "o"), *options]
                if command != "live" else [command, str(tmp_path / "missing.mp4"), *options]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err, err


def test_detect_body_mode_finds_no_hands(tmp_path, capsys):
    """``detect --mode body`` (and ``--no-hands``, its old name): the body's keypoints as in the whole mode, the
    hands zero (none looked for)."""
    image = Path(__file__).parent / "data" / "messi5.jpg"
    people = {}
    for name, mode in (("whole", ["--mode", "whole"]), ("body", ["--mode", "body"]), ("no-hands", ["--no-hands"])):
        assert main(["detect", str(image), "--out", str(tmp_path / name), "--quiet", *mode]) == 0
        people[name] = json.loads((tmp_path / name / "messi5_keypoints.json").read_text())["people"]
    assert any(people["whole"][0]["hand_right_keypoints_2d"]) or any(people["whole"][0]["hand_left_keypoints_2d"])
    assert people["body"] == people["no-hands"] and len(people["body"]) == len(people["whole"]) >= 1
    for body, whole in zip(people["body"], people["whole"]):
        assert body["pose_keypoints_2d"] == whole["pose_keypoints_2d"]
        assert not any(body["hand_left_keypoints_2d"]) and not any(body["hand_right_keypoints_2d"])


def test_detect_says_which_landmark_model_ran_and_falls_back_to_full_without_npm(tmp_path, capsys, monkeypatch):
    """``detect`` runs heavy by default and says so; with npm hidden from PATH and no copy of heavy, one line says
    how to provide it and the keypoints come from full (as ``--landmarks full`` gives them); ``live`` runs full
    by default."""
    from jaxmocap.detect import ensure_models
    from jaxmocap.live import LiveConfig

    image = Path(__file__).parent / "data" / "messi5.jpg"

    def detect(name, *options):
        assert main(["detect", str(image), "--out", str(tmp_path / name), "--quiet", "--mode", "body", *options]) == 0
        out, err = capsys.readouterr()
        return out, err, json.loads((tmp_path / name / "messi5_keypoints.json").read_text())["people"]

    out, err, heavy = detect("heavy")
    assert "(BlazePose heavy)" in out and not err
    out, _, full = detect("full", "--landmarks", "full")
    assert "(BlazePose full)" in out and full != heavy
    wheel_files = ensure_models()["pose_detection.tflite"].parent
    monkeypatch.setenv("JAXMOCAP_CACHE", str(tmp_path / "cache"))
    monkeypatch.delenv("JAXMOCAP_MEDIAPIPE_DIR", raising=False)
    (tmp_path / "cache").mkdir()
    (tmp_path / "cache" / wheel_files.name).symlink_to(wheel_files)
    monkeypatch.setenv("PATH", str(tmp_path / "no-npm"))
    out, err, fallen_back = detect("fallback")
    assert "(BlazePose full)" in out and fallen_back == full
    assert err.count("\n") == 1 and err.startswith("notice: ") and "npm pack @mediapipe/pose@" in err, err
    assert LiveConfig("0").landmarks == "full"


def test_live_body_mode_builds_no_hand_model():
    """``live --mode body``: the detector without hands and the causal step without the hands' IK."""
    from jaxmocap.live import LiveConfig
    from jaxmocap.live.session import Session

    clip = Path(__file__).parents[1] / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"
    for mode, hands in (("body", False), ("whole", True)):
        session = Session(LiveConfig(clip, mode=mode, progress=False))
        try:
            assert session.detector.with_hands is hands and session.solver.settings.hands is hands
            assert (session.detector._hands is not None) is hands
        finally:
            session.close()
