"""Ctrl-C at random moments of ``jaxmocap run``: every run must end with 130 (or 0, where it had finished) and no
traceback, abort or crash on stderr, and run again it must resume to the motion of a run never interrupted. Too
long for the suite (each run starts a process); run by hand after changes to stopping or writing:

    .venv/bin/python tests/stress_interrupts.py --runs 200

Each run solves the first ``--frames`` frames of the sample clip in chunks of ``--chunk``; its Ctrl-C comes at a
moment drawn uniformly over a whole run's time (so a few land before the command starts, a few after it ends);
every ``--resume-every``-th run, and every failed one, is run again and compared. Prints one JSON line a run and
the count of failures; exits 1 when there is one.
"""

import argparse
import json
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).parents[1]
CLIP = ROOT / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"
# the command as from a terminal: Ctrl-C's handler Python's own (a background job inherits SIGINT ignored)
START = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
         "from jaxmocap.command import entry; entry()")
PROBLEMS = ("Traceback", "Exception ignored", "Fatal Python error", "Aborted", "terminate called", "Segmentation")


def command(out: Path, frames: int, chunk: int) -> list[str]:
    return [sys.executable, "-X", "faulthandler", "-c", START, "run", str(CLIP), "--out", str(out), "--end",
            str(frames), "--chunk", str(chunk), "--quiet"]


def same_motion(a: Path, b: Path) -> bool:
    with np.load(a) as x, np.load(b) as y:
        return sorted(x.files) == sorted(y.files) and all(np.array_equal(x[k], y[k]) for k in x.files)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=200)
    parser.add_argument("--frames", type=int, default=24)
    parser.add_argument("--chunk", type=int, default=8)
    parser.add_argument("--resume-every", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    work = Path(tempfile.mkdtemp(prefix="jaxmocap-interrupts-"))
    run = lambda out: subprocess.run(command(out, args.frames, args.chunk), capture_output=True, text=True,  # noqa: E731
                                     cwd=ROOT)
    assert run(work / "reference").returncode == 0, "the reference run failed"
    started = time.monotonic()
    run(work / "timed")  # a whole run's time, its compiled programs cached as the interrupted runs' are
    whole = time.monotonic() - started
    print(json.dumps({"whole_run_s": round(whole, 1), "frames": args.frames, "chunk": args.chunk}), flush=True)
    rng, failures = random.Random(args.seed), 0
    for k in range(args.runs):
        out, at = work / f"run{k}", rng.uniform(0.0, 1.05 * whole)
        process = subprocess.Popen(command(out, args.frames, args.chunk), stdout=subprocess.PIPE,
                                   stderr=subprocess.PIPE, text=True, cwd=ROOT)
        time.sleep(at)
        process.send_signal(signal.SIGINT)
        try:
            _, err = process.communicate(timeout=120)
        except subprocess.TimeoutExpired:  # a hang: every thread's stack into stderr
            process.send_signal(signal.SIGABRT)
            _, err = process.communicate()
        line = {"run": k, "at_s": round(at, 2), "exit": process.returncode,
                "problems": [p for p in PROBLEMS if p in err]}
        ok = process.returncode in (0, 130) and not line["problems"]
        if k % args.resume_every == 0 or not ok:
            resumed = run(out)
            line["resumed_same"] = resumed.returncode == 0 and same_motion(out / "motion.npz",
                                                                           work / "reference" / "motion.npz")
            ok = ok and line["resumed_same"]
        if not ok:
            failures += 1
            line["stderr"] = err[-3000:]
        print(json.dumps(line), flush=True)
        shutil.rmtree(out, ignore_errors=True)
    print(json.dumps({"runs": args.runs, "failures": failures}))
    shutil.rmtree(work, ignore_errors=True)
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
