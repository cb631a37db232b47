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

Found where mediapipe finds (issue 70's hands): the close-up as shot, blurred (Gaussian sigma 2 and 4 px: out of
focus, or moving), scaled by 1/2 and 1/4 (a hand 50 and 25 px long), each also mirrored (a left hand), tracked by
our tracker as a hands run tracks it (up to two hands) and by the peer's ``Hands`` (video mode, ``max_num_hands``
2) on the same frames: the frames where the peer finds a hand, those of them where ours finds none, and the frames
only ours finds one. Likewise the hand images the project ships (``tests/data/*.jpg``) and the same degraded
versions, each on its own (``static_image_mode``): the hands each finds (matched by their wrists, within a tenth of
the image's long side).
"""

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

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

PEER_FOUND = r"""
import json, sys, cv2, numpy as np, mediapipe as mp
versions, images = np.load(sys.argv[1]), np.load(sys.argv[2])
out = {"video": {}, "images": {}}
for name in versions.files:
    frames = versions[name]
    with mp.solutions.hands.Hands(static_image_mode=False, max_num_hands=2, model_complexity=1) as h:
        out["video"][name] = [len(h.process(cv2.cvtColor(f, cv2.COLOR_BGR2RGB)).multi_hand_landmarks or [])
                              for f in frames]
with mp.solutions.hands.Hands(static_image_mode=True, max_num_hands=2, model_complexity=1) as h:
    for name in images.files:
        image = images[name]
        found = h.process(cv2.cvtColor(image, cv2.COLOR_BGR2RGB)).multi_hand_landmarks or []
        out["images"][name] = [[lm.landmark[0].x * image.shape[1], lm.landmark[0].y * image.shape[0]] for lm in found]
print(json.dumps({"version": mp.__version__, "results": out}))
"""
BLUR_PX = (2.0, 4.0)
SCALES = (0.5, 0.25)
WRIST_MATCH = 0.1  # of the image's long side: two wrists this close are one hand


def degraded(image: np.ndarray) -> dict[str, np.ndarray]:
    """``image`` as shot, blurred by each of `BLUR_PX`, scaled by each of `SCALES`; each also mirrored."""
    import cv2

    out = {}
    for mirrored in (False, True):
        shot = cv2.flip(image, 1) if mirrored else image
        side = "mirrored, " if mirrored else ""
        out[f"{side}as shot"] = shot
        out |= {f"{side}blur {b:g} px": cv2.GaussianBlur(shot, (0, 0), b) for b in BLUR_PX}
        out |= {f"{side}scale {k:g}": cv2.resize(shot, None, fx=k, fy=k, interpolation=cv2.INTER_AREA)
                for k in SCALES}
    return out


def found_where_mediapipe_finds(frames: list[np.ndarray], peer_python: str | None) -> dict:
    """The close-up's and the shipped images' degraded versions (`degraded`), hands found by ours and the peer."""
    import cv2

    from jaxmocap.detect.hand_tracker import HandTracker

    by_frame = [degraded(frame) for frame in frames]
    versions = {name: [d[name] for d in by_frame] for name in by_frame[0]}
    images = {f"{path.name}: {name}": image for path in sorted((ROOT / "tests" / "data").glob("*.jpg"))
              for name, image in degraded(cv2.imread(str(path))).items()}
    with tempfile.TemporaryDirectory() as tmp:
        np.savez(Path(tmp) / "versions.npz", **{name: np.stack(frames) for name, frames in versions.items()})
        np.savez(Path(tmp) / "images.npz", **images)
        peer = run_peer(peer_python, PEER_FOUND, Path(tmp) / "versions.npz", Path(tmp) / "images.npz")["results"]
    rows = {}
    for name, version in versions.items():
        tracker = HandTracker(static_image_mode=False, max_hands=2)
        ours = np.array([len(tracker(frame)) > 0 for frame in version])
        theirs = np.array(peer["video"][name]) > 0 if peer else np.zeros(len(ours), bool)
        rows[name] = {"mediapipe": int(theirs.sum()) if peer else None, "ours": int(ours.sum()),
                      "missed": np.flatnonzero(theirs & ~ours).tolist(), "ours_only": int((ours & ~theirs).sum())}
    still = HandTracker(static_image_mode=True, max_hands=2)
    matched = {"mediapipe": 0, "ours": 0, "missed": [], "ours_only": []}
    for name, image in images.items():
        ours = np.array([hand.keypoints[0, :2] for hand in still(image)]).reshape(-1, 2)
        theirs = np.array(peer["images"][name] if peer else []).reshape(-1, 2)
        near = np.linalg.norm(ours[:, None] - theirs[None], axis=-1) < WRIST_MATCH * max(image.shape[:2])
        matched["mediapipe"] += len(theirs)
        matched["ours"] += len(ours)
        matched["missed"] += [name] * int((~near.any(0)).sum())
        matched["ours_only"] += [name] * int((~near.any(1)).sum())
    return {"video": rows, "images": matched, "images_count": len(images)}


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
    found = found_where_mediapipe_finds(frames, peer_python)
    print(f"\nfound where mediapipe {peer['version'] or '(not run)'} Hands finds: {CLIP.name}, up to two hands")
    print(f"{'version':<26}{'mediapipe':>10}{'ours':>6}{'missed':>8}{'ours only':>11}   frames missed")
    for name, row in found["video"].items():
        print(f"{name:<26}{row['mediapipe'] if row['mediapipe'] is not None else 'n/a':>10}{row['ours']:>6}"
              f"{len(row['missed']):>8}{row['ours_only']:>11}   {row['missed']}")
    images = found["images"]
    print(f"{found['images_count']} images (tests/data/*.jpg, each degraded as above), each on its own: hands "
          f"mediapipe {images['mediapipe']}, ours {images['ours']}, missed {images['missed']}, ours only "
          f"{images['ours_only']}")
    out = args.out / "hands.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"clip": CLIP.name, "frames": len(frames), "cpus": os.cpu_count(), "rows": rows,
                               "found_where_mediapipe_finds": found}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    from jaxmocap.xla_options import configure_process

    configure_process()  # a command of the project: its process's settings before JAX starts
    main()
