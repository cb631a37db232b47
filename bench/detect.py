"""Detector speed in tracking (video) mode, ours vs official mediapipe 0.10.21, on the bundled Pose2Sim clip;
and agreement on still images (`STILLS`: frames of the clips the tests do not compare, as shot and mirrored).

    python bench/detect.py [--out bench/results] [--quick] [--frames N] [--mediapipe-python PATH]

Ours: ``jaxmocap.detect.Detector(static_image_mode=False)`` (pose + hands, LiteRT, 2 threads). Peer: the legacy
``mp.solutions.holistic.Holistic`` (pose + hands, face off is impossible in legacy holistic, so also
``mp.solutions.pose`` + ``mp.solutions.hands`` run one after the other), in the mediapipe venv as a subprocess, same
frames, same machine, same run. Stills: ``Detector(static_image_mode=True, landmarks=...)`` (one person, bodies)
for each BlazePose landmark model against the legacy ``mp.solutions.pose.Pose(static_image_mode=True,
model_complexity=c)`` on the same images (heavy: 2, full: 1, lite: 0; the wheel bundles only full, so heavy and
lite, from jaxmocap's cache, are copied into the peer's ``mediapipe/modules/pose_landmark/``, where the legacy
solution looks before it would download them): the pixel distance of the 33 landmarks (median over all points,
and each image's median), images where only one of the two finds a person. Prints tables and writes
``<out>/detect.json``.

The peer needs an environment of its own, outside the clone (mediapipe 0.10.21 pins numpy<2 and cannot share
jaxmocap's): ``python3 -m venv ~/venvs/mediapipe && ~/venvs/mediapipe/bin/pip install mediapipe==0.10.21``, then
``--mediapipe-python ~/venvs/mediapipe/bin/python`` or ``JAXMOCAP_MEDIAPIPE_PYTHON=~/venvs/mediapipe/bin/python``
(docs/BENCHMARKS.md, "Detector"). Without either, the peer's rows read "n/a" and a line says how to make it.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
CLIP = ROOT / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"

PEER = r"""
import json, sys, time, cv2, mediapipe as mp
clip, n = sys.argv[1], int(sys.argv[2])
cap = cv2.VideoCapture(clip); frames = []
while len(frames) < n:
    ok, f = cap.read()
    if not ok: break
    frames.append(cv2.cvtColor(f, cv2.COLOR_BGR2RGB))
def timed(process, warm=3):
    for f in frames[:warm]: process(f)
    t = time.perf_counter(); found = [0, 0]
    for f in frames:
        b, h = process(f); found[0] += b; found[1] += h
    return (time.perf_counter() - t) * 1000 / len(frames), found[0], found[1]
out = {}
with mp.solutions.holistic.Holistic(static_image_mode=False, model_complexity=1) as h:
    def hol(f):
        r = h.process(f)
        hands = (r.left_hand_landmarks is not None) + (r.right_hand_landmarks is not None)
        return int(r.pose_landmarks is not None), hands
    out["holistic"] = timed(hol)
with mp.solutions.pose.Pose(static_image_mode=False, model_complexity=1) as p, \
        mp.solutions.hands.Hands(static_image_mode=False, max_num_hands=2, model_complexity=1) as hd:
    out["pose+hands"] = timed(lambda f: (int(p.process(f).pose_landmarks is not None),
                                         len(hd.process(f).multi_hand_landmarks or [])))
with mp.solutions.pose.Pose(static_image_mode=False, model_complexity=1) as p:
    out["pose"] = timed(lambda f: (int(p.process(f).pose_landmarks is not None), 0))
print(json.dumps({"version": mp.__version__, "results": out}))
"""


MEDIAPIPE_VERSION = "0.10.21"
MEDIAPIPE_ENV = "JAXMOCAP_MEDIAPIPE_PYTHON"
SETUP = (f"Make the peer's environment outside the clone with `python3 -m venv ~/venvs/mediapipe && "
         f"~/venvs/mediapipe/bin/pip install mediapipe=={MEDIAPIPE_VERSION}` and pass "
         f"`--mediapipe-python ~/venvs/mediapipe/bin/python` or set {MEDIAPIPE_ENV}.")


def mediapipe_python(given: str | None) -> str | None:
    """The peer's Python: ``given`` (the option, else ``$JAXMOCAP_MEDIAPIPE_PYTHON``); None, with a line that says
    how to make it, when neither is set; exits with a one-line error when the path given is not a file."""
    if not given:
        print(f"mediapipe peer skipped: no --mediapipe-python and no ${MEDIAPIPE_ENV}; its rows read n/a. {SETUP}",
              file=sys.stderr)
        return None
    path = Path(given).expanduser()
    if not path.is_file():
        raise SystemExit(f"bench/detect.py: the mediapipe Python {given} (--mediapipe-python or ${MEDIAPIPE_ENV}) "
                         f"does not exist. {SETUP}")
    return str(path)


PEER_STILLS = r"""
import json, sys, cv2, numpy as np, mediapipe as mp
out = {}
with mp.solutions.pose.Pose(static_image_mode=True, model_complexity=int(sys.argv[1])) as pose:
    for path in sys.argv[2:]:
        bgr = cv2.imread(path); h, w = bgr.shape[:2]
        res = pose.process(cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
        out[path] = None if res.pose_landmarks is None else [
            [lm.x * w, lm.y * h] for lm in res.pose_landmarks.landmark]
print(json.dumps({"version": mp.__version__, "results": out}))
"""
COMPLEXITY = {"heavy": 2, "full": 1, "lite": 0}  # the legacy solution's model_complexity of each landmark model
PEER_FOLDER = r"""
import os, mediapipe
print(os.path.join(os.path.dirname(mediapipe.__file__), "modules", "pose_landmark"))
"""


def give_peer_landmark_models(peer_python: str) -> None:
    """Heavy and lite from jaxmocap's verified cache into the peer's package, where ``model_complexity`` 2 and 0
    look for them (the wheel bundles full alone)."""
    import shutil

    from jaxmocap.detect.models import NPM_FILES, model_path

    folder = Path(subprocess.run([peer_python, "-c", PEER_FOLDER], capture_output=True, text=True,
                                 check=True).stdout.strip())
    for name in NPM_FILES:
        if not (folder / name).is_file():
            shutil.copy(model_path(name), folder / name)
            print(f"copied {name} into the peer's {folder}", file=sys.stderr)
# (clip, frames): the single-person take's other view and the two-person take, none of them compared in the tests
STILLS = (("pose2sim_single_cam03.mp4", (0, 30, 60, 90)), ("pose2sim_multi_cam01.mp4", (0, 50, 99)))


def write_stills(folder: Path) -> list[Path]:
    """`STILLS` as JPEG files in ``folder``, each also mirrored."""
    import cv2

    paths = []
    for clip, indices in STILLS:
        cap = cv2.VideoCapture(str(ROOT / "tests" / "data" / clip))
        for index in indices:
            cap.set(cv2.CAP_PROP_POS_FRAMES, index)
            ok, frame = cap.read()
            if not ok:
                raise SystemExit(f"bench/detect.py: cannot read frame {index} of {clip}")
            for name, image in ((f"{Path(clip).stem}_f{index:03d}", frame),
                                (f"{Path(clip).stem}_f{index:03d}_mirror", frame[:, ::-1])):
                paths.append(folder / f"{name}.jpg")
                cv2.imwrite(str(paths[-1]), np.ascontiguousarray(image), [cv2.IMWRITE_JPEG_QUALITY, 95])
    return paths


def compare_stills(paths: list[Path], peer: dict, landmarks: str) -> dict:
    """Ours against the peer's landmarks on each still (as the file reads back: both decode the same JPEG), with
    the landmark model ``landmarks``."""
    import cv2

    from jaxmocap.detect import Detector

    detector = Detector(static_image_mode=True, hands=False, landmarks=landmarks)
    images, distances, missed = {}, [], []
    for path in paths:
        people = detector(cv2.imread(str(path)))
        theirs = peer["results"].get(str(path))
        if (theirs is None) != (not people):
            missed.append(path.name)
            continue
        if theirs is None:
            continue
        d = np.linalg.norm(people[0].body[:, :2] - np.asarray(theirs), axis=1)
        images[path.name] = float(np.median(d))
        distances.append(d)
    all_points = np.concatenate(distances) if distances else np.zeros(0)
    return {"images": images, "missed": missed, "points": int(all_points.size),
            "median_px": float(np.median(all_points)) if all_points.size else None,
            "p90_px": float(np.percentile(all_points, 90)) if all_points.size else None}


def run_peer(peer_python: str | None, script: str, *args) -> dict:
    """The peer's JSON result of ``script`` with ``args`` in the mediapipe Python; without it, or when it fails (a
    line says why), no results."""
    if peer_python is not None:
        proc = subprocess.run([peer_python, "-c", script, *map(str, args)], capture_output=True, text=True)
        if proc.returncode == 0:
            return json.loads(proc.stdout.strip().splitlines()[-1])
        last = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        print(f"mediapipe peer failed in {peer_python} ({last}); its rows read n/a. {SETUP}", file=sys.stderr)
    return {"version": None, "results": {}}


def read_frames(n: int):
    import cv2

    cap = cv2.VideoCapture(str(CLIP))
    frames = []
    while len(frames) < n:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame)
    return frames


def time_ours(frames, hands: bool, warm: int = 3) -> tuple[float, int, int]:
    from jaxmocap.detect import Detector

    det = Detector(static_image_mode=False, hands=hands)
    for f in frames[:warm]:
        det(f)
    det.reset()
    start = time.perf_counter()
    bodies = hand_count = 0
    for f in frames:
        people = det(f)
        bodies += bool(people)
        hand_count += sum((p.left_hand is not None) + (p.right_hand is not None) for p in people)
    return (time.perf_counter() - start) * 1000 / len(frames), bodies, hand_count


def main() -> None:
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    parser.add_argument("--quick", action="store_true", help="30 frames")
    parser.add_argument("--frames", type=int, default=100)
    parser.add_argument("--mediapipe-python", metavar="PATH", default=os.environ.get(MEDIAPIPE_ENV) or None,
                        help=f"the Python of a venv with mediapipe=={MEDIAPIPE_VERSION} (default: ${MEDIAPIPE_ENV})")
    args = parser.parse_args()
    peer_python = mediapipe_python(args.mediapipe_python)
    frames = read_frames(30 if args.quick else args.frames)
    rows = {}
    ms, bodies, hands = time_ours(frames, hands=True)
    rows["jaxmocap pose+hands (tracking)"] = {"ms_per_frame": ms, "frames_with_body": bodies, "hands": hands}
    ms, bodies, _ = time_ours(frames, hands=False)
    rows["jaxmocap pose (tracking)"] = {"ms_per_frame": ms, "frames_with_body": bodies}
    peer = run_peer(peer_python, PEER, CLIP, len(frames))
    for name in ("holistic", "pose+hands", "pose"):
        value = peer["results"].get(name)
        rows[f"mediapipe {peer['version'] or ''} {name} (video mode)".replace("  ", " ")] = (
            {"ms_per_frame": value[0], "frames_with_body": value[1], "hands": value[2]} if value
            else {"ms_per_frame": "n/a"})
    print(f"{len(frames)} frames of {CLIP.name} ({frames[0].shape[1]}x{frames[0].shape[0]}), "
          f"{os.cpu_count()} CPUs, {platform.processor() or platform.machine()}")
    print(f"{'pipeline':<48}{'ms/frame':>10}{'body found':>12}{'hands found':>13}")
    for name, row in rows.items():
        ms = row["ms_per_frame"]
        ms_text = f"{ms:.1f}" if isinstance(ms, float) else ms
        print(f"{name:<48}{ms_text:>10}{row.get('frames_with_body', ''):>12}{row.get('hands', ''):>13}")
    stills = {}
    if peer_python is not None:
        give_peer_landmark_models(peer_python)
    with tempfile.TemporaryDirectory() as folder:
        paths = write_stills(Path(folder))
        for landmarks, complexity in COMPLEXITY.items():
            peer = run_peer(peer_python, PEER_STILLS, complexity, *paths)
            if peer["version"] is not None:
                stills[landmarks] = compare_stills(paths, peer, landmarks)
    if not stills:
        print("stills against mediapipe: n/a (no peer)")
    for landmarks, found in stills.items():
        print(f"{len(paths)} stills, BlazePose {landmarks} against mediapipe {peer['version']} (pose, static, "
              f"complexity {COMPLEXITY[landmarks]}): median {found['median_px']:.2f} px over {found['points']} "
              f"points, 90th percentile {found['p90_px']:.2f} px, missed {len(found['missed'])} {found['missed']}")
        for name, px in found["images"].items():
            print(f"  {name:<44}{px:>8.2f} px")
    out = args.out / "detect.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"clip": CLIP.name, "frames": len(frames), "cpus": os.cpu_count(), "rows": rows,
                               "stills": stills}, indent=1))
    print(f"wrote {out}")


if __name__ == "__main__":
    from jaxmocap.xla_options import configure_process

    configure_process()  # a command of the project: its process's settings before JAX starts
    main()
