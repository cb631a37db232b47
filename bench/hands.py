"""Hands on their own: ``jaxmocap run --mode hands`` on a hand close-up video (one hand), end to end, beside the
official mediapipe hand solution's landmarks-only speed on the same frames; and our hand tracker alone.

    python bench/hands.py [--out bench/results] [--quick] [--mediapipe-python PATH]

The clip is ``tests/data/pose2sim_hand_closeup.mp4`` (the bundled clip cropped around the right hand, 320x320, 100
frames; `bench/checks/hand_closeup.py`). Our run goes twice in one process: the first includes JAX tracing and
compilation, the second is the steady state (``--quick``: first runs only); with and without the overlay video.
Frames/s counts the run's stages, as ``bench/pipeline.py`` and the command's summary line do; ``wall s`` adds what
a run does once (loading the body model, opening the models and the video: about a second).
The peer is mediapipe 0.10.21's legacy ``mp.solutions.hands.Hands`` in video mode (``max_num_hands`` 1 and 2,
model complexity 1), landmarks only, timed per ``process`` call after 3 warm-up frames, in its own venv as in
``bench/detect.py``. Prints a table and writes ``<out>/hands.json``.
"""

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLIP = ROOT / "tests" / "data" / "pose2sim_hand_closeup.mp4"
sys.path.insert(0, str(ROOT / "bench"))

from detect import MEDIAPIPE_ENV, MEDIAPIPE_VERSION, mediapipe_python, run_peer  # noqa: E402

PEER = r"""
import json, sys, time, cv2, mediapipe as mp
clip, n = sys.argv[1], int(sys.argv[2])
cap = cv2.VideoCapture(clip); frames = []
while len(frames) < n:
    ok, f = cap.read()
    if not ok: break
    frames.append(cv2.cvtColor(f, cv2.COLOR_BGR2RGB))
out = {}
for hands in (1, 2):
    with mp.solutions.hands.Hands(static_image_mode=False, max_num_hands=hands, model_complexity=1) as h:
        for f in frames[:3]: h.process(f)
        t = time.perf_counter(); found = 0
        for f in frames:
            found += bool(h.process(f).multi_hand_landmarks)
        out[hands] = ((time.perf_counter() - t) * 1000 / len(frames), found)
print(json.dumps({"version": mp.__version__, "results": out}))
"""


def ours_tracker(frames, max_hands: int) -> tuple[float, int]:
    """Our hand tracker alone (landmarks only), ms/frame and frames with a hand."""
    from jaxmocap.detect.hand_tracker import HandTracker

    tracker = HandTracker(static_image_mode=False, max_hands=max_hands)
    for frame in frames[:3]:
        tracker(frame)
    tracker.reset()
    start, found = time.perf_counter(), 0
    for frame in frames:
        found += bool(tracker(frame))
    return (time.perf_counter() - start) * 1000 / len(frames), found


def ours_run(end: int, overlay: bool) -> dict:
    from jaxmocap.hand_motion import read_hands
    from jaxmocap.pipeline import RunConfig, run

    with tempfile.TemporaryDirectory() as out:
        start = time.perf_counter()
        report = run(RunConfig(CLIP, mode="hands", end=end, overlay=overlay, progress=False), out)
        wall = time.perf_counter() - start
        hands = read_hands(report.motion)
    stages = sum(report.seconds.values())
    return {"frames_per_s": report.frames / stages, "seconds": stages, "wall_seconds": wall, "valid": report.valid,
            "ms_per_frame": {k: 1000 * v / report.frames for k, v in report.seconds.items()},
            "median_error_px": float(_median_error(hands))}


def _median_error(hands) -> float:
    import numpy as np

    valid = hands["right_valid"]
    return np.median(hands["right_reprojection_error_px"][valid]) if valid.any() else float("nan")


def main() -> None:
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    parser.add_argument("--quick", action="store_true", help="first runs only (compilation included)")
    parser.add_argument("--mediapipe-python", metavar="PATH", default=os.environ.get(MEDIAPIPE_ENV) or None,
                        help=f"the Python of a venv with mediapipe=={MEDIAPIPE_VERSION} (default: ${MEDIAPIPE_ENV})")
    args = parser.parse_args()
    peer_python = mediapipe_python(args.mediapipe_python)

    import cv2

    capture = cv2.VideoCapture(str(CLIP))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            break
        frames.append(frame)
    rows = {}
    for overlay in (True, False):
        name = f"jaxmocap run --mode hands{'' if overlay else ' --no-overlay'}"
        rows[f"{name} (first run)"] = ours_run(len(frames), overlay)
        if not args.quick:
            rows[f"{name} (steady)"] = ours_run(len(frames), overlay)
    for hands in (1, 2):
        ms, found = ours_tracker(frames, hands)
        rows[f"jaxmocap hand tracker, max {hands} hand(s)"] = {"frames_per_s": 1000 / ms, "ms_per_frame": ms,
                                                               "valid": found}
    peer = run_peer(peer_python, PEER, CLIP, len(frames))
    for hands in ("1", "2"):
        value = peer["results"].get(hands)
        name = f"mediapipe {peer['version'] or ''} hands, max {hands} hand(s), landmarks only".replace("  ", " ")
        rows[name] = {"frames_per_s": 1000 / value[0], "ms_per_frame": value[0], "valid": value[1]} if value \
            else {"frames_per_s": "n/a"}

    print(f"{len(frames)} frames of {CLIP.name} ({frames[0].shape[1]}x{frames[0].shape[0]}), one hand, "
          f"{os.cpu_count()} CPUs, {platform.processor() or platform.machine()}")
    print(f"{'pipeline':<62}{'frames/s':>10}{'wall s':>8}{'hand found':>12}   stages (ms/frame)")
    for name, row in rows.items():
        fps, wall = row["frames_per_s"], row.get("wall_seconds")
        stages = row["ms_per_frame"] if isinstance(row.get("ms_per_frame"), dict) else {}
        print(f"{name:<62}{fps if isinstance(fps, str) else f'{fps:.1f}':>10}{f'{wall:.1f}' if wall else '':>8}"
              f"{row.get('valid', ''):>12}   " + ", ".join(f"{k} {v:.1f}" for k, v in stages.items()))
    out = args.out / "hands.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"clip": CLIP.name, "frames": len(frames), "cpus": os.cpu_count(), "rows": rows},
                              indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    from jaxmocap.xla_options import configure_process

    configure_process()  # a command of the project: its process's settings before JAX starts
    main()
