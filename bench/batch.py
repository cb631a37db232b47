"""Many videos: ``jaxmocap batch --workers 2`` against four ``jaxmocap run`` calls one after another, in one run.

    python bench/batch.py [--out bench/results] [--quick]      (or: jaxmocap bench --only batch)

Four clips of 100 frames at 60 fps (the single-person take's two views, cam01 and cam03, each also mirrored), no
overlay, as a user runs them, each command a new process:
- ``run, own caches``: four ``jaxmocap run``, each with an empty compile cache of its own (each compiles everything);
- ``run, shared cache``: four ``jaxmocap run`` sharing one new cache (the first compiles, the others read it back);
- ``batch, 2 workers``: one ``jaxmocap batch`` of the four on a local Ray with two workers and one new cache.
Throughput is frames over wall time (process start, imports and Ray's start included); the compile time the shared
cache saves is the difference between the first two, per run after the first. The batch's motions are compared
with the shared-cache runs'. ``--quick``: the first 30 frames of each clip, and no ``own caches`` runs.
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
VIEWS = {"cam01": ROOT / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4",
         "cam03": ROOT / "tests" / "data" / "pose2sim_single_cam03.mp4"}
OPTIONS = ["--no-overlay", "--quiet"]


def write_clips(folder: Path, frames: int) -> list[Path]:
    """Each view as it is and mirrored, its first ``frames`` frames, re-encoded alike (mp4v)."""
    folder.mkdir(parents=True, exist_ok=True)
    clips = []
    for name, source in VIEWS.items():
        for mirrored in (False, True):
            path = folder / f"{name}{'_mirrored' if mirrored else ''}.mp4"
            capture = cv2.VideoCapture(str(source))
            size = (int(capture.get(cv2.CAP_PROP_FRAME_WIDTH)), int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT)))
            writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), capture.get(cv2.CAP_PROP_FPS), size)
            for _ in range(frames):
                ok, image = capture.read()
                if not ok:
                    break
                writer.write(image[:, ::-1] if mirrored else image)
            writer.release()
            capture.release()
            if not cv2.VideoCapture(str(path)).isOpened():
                raise SystemExit(f"could not write {path}")
            clips.append(path)
    return clips


def timed(command: list[str], env: dict) -> float:
    started = time.perf_counter()
    proc = subprocess.run(command, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed ({proc.returncode}): {proc.stderr.strip()[-2000:]}")
    return time.perf_counter() - started


def jaxmocap(*args) -> list[str]:
    return [sys.executable, "-m", "jaxmocap.cli", *map(str, args)]


def environment(cache: Path, ray_dir: Path) -> dict:
    return os.environ | {"JAX_COMPILATION_CACHE_DIR": str(cache), "RAY_TMPDIR": str(ray_dir)}


def sequential_runs(clips: list[Path], root: Path, shared: bool, ray_dir: Path) -> tuple[list[float], Path]:
    """Four ``jaxmocap run``, one after another: the seconds of each, and the folder of their outputs."""
    out = root / ("shared" if shared else "own")
    seconds = []
    for clip in clips:
        cache = root / "caches" / ("shared" if shared else clip.stem)
        seconds.append(timed(jaxmocap("run", clip, "--out", out / clip.stem, *OPTIONS),
                             environment(cache, ray_dir)))
        print(f"  run {clip.stem} ({'shared' if shared else 'own'} cache): {seconds[-1]:.1f} s", flush=True)
    return seconds, out


def max_difference(ours: Path, theirs: Path) -> float:
    a, b = np.load(ours), np.load(theirs)
    return max(float(np.abs(a[k].astype(np.float64) - b[k].astype(np.float64)).max()) for k in b.files
               if b[k].dtype.kind in "fiub")


def main():
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results"))
    parser.add_argument("--quick", action="store_true", help="30 frames per clip, no own-cache runs")
    args = parser.parse_args()

    frames = 30 if args.quick else 100
    with tempfile.TemporaryDirectory(prefix="jaxmocap-bench-batch-") as tmp, \
            tempfile.TemporaryDirectory(prefix="ray-", dir="/tmp") as ray_dir:
        root = Path(tmp)
        clips = write_clips(root / "clips", frames)
        total = sum(int(cv2.VideoCapture(str(c)).get(cv2.CAP_PROP_FRAME_COUNT)) for c in clips)
        rows = []
        if not args.quick:
            own, _ = sequential_runs(clips, root, shared=False, ray_dir=Path(ray_dir))
            rows.append(dict(arm="run, own caches", seconds=sum(own), per_video=own))
        shared, shared_out = sequential_runs(clips, root, shared=True, ray_dir=Path(ray_dir))
        rows.append(dict(arm="run, shared cache", seconds=sum(shared), per_video=shared))
        batch_out = root / "batch"
        seconds = timed(jaxmocap("batch", *clips, "--out", batch_out, "--workers", 2, *OPTIONS),
                        environment(root / "caches" / "batch", Path(ray_dir)))
        videos = json.loads((batch_out / "batch.json").read_text())["videos"]
        assert all(v["status"] == "done" for v in videos), videos
        rows.append(dict(arm="batch, 2 workers", seconds=seconds, per_video=[v["seconds"] for v in videos]))
        second = timed(jaxmocap("batch", *clips, "--out", batch_out, "--workers", 2, *OPTIONS),
                       environment(root / "caches" / "batch", Path(ray_dir)))
        difference = max(max_difference(batch_out / c.stem / "motion.npz", shared_out / c.stem / "motion.npz")
                         for c in clips)
        written = [p for c in clips for p in (batch_out / c.stem).rglob("*") if p.is_file()]
        storage = dict(bytes_per_frame=sum(p.stat().st_size for p in written) / total,
                       files_per_frame=len(written) / total)

    for row in rows:
        row |= dict(frames=total, fps=total / row["seconds"], videos_per_hour=3600 * len(clips) / row["seconds"])
    by_arm = {r["arm"]: r for r in rows}
    result = dict(benchmark="batch", cpus=os.cpu_count(), machine=platform.machine(), clips=[c.name for c in clips],
                  frames_per_clip=frames, rows=rows, second_call_seconds=second, max_abs_difference=difference,
                  storage=storage,
                  throughput_ratio=by_arm["batch, 2 workers"]["fps"] / by_arm["run, shared cache"]["fps"])
    if "run, own caches" in by_arm:
        own, shared = by_arm["run, own caches"]["per_video"], by_arm["run, shared cache"]["per_video"]
        result |= dict(compile_saved_per_run=float(np.mean(own[1:]) - np.mean(shared[1:])),
                       compile_saved_total=sum(own[1:]) - sum(shared[1:]),
                       throughput_ratio_own_caches=by_arm["batch, 2 workers"]["fps"] / by_arm["run, own caches"]["fps"])

    print(f"\n{len(clips)} clips x {frames} frames ({', '.join(c.stem for c in clips)}), no overlay, "
          f"{os.cpu_count()} CPUs, {platform.machine()}")
    print(f"{'':<20}{'wall s':>8}{'frames/s':>10}{'videos/h':>10}   per video s")
    for r in rows:
        print(f"{r['arm']:<20}{r['seconds']:>8.1f}{r['fps']:>10.2f}{r['videos_per_hour']:>10.0f}   "
              + " ".join(f"{s:.1f}" for s in r["per_video"]))
    print(f"batch / run (shared cache) throughput: {result['throughput_ratio']:.2f}x"
          + (f"; / run (own caches): {result['throughput_ratio_own_caches']:.2f}x" if "compile_saved_total" in result
             else ""))
    if "compile_saved_total" in result:
        print(f"compile time the shared cache saves: {result['compile_saved_per_run']:.1f} s per run after the "
              f"first ({result['compile_saved_total']:.1f} s over runs 2-4)")
    print(f"second batch call (all finished): {second:.1f} s; batch vs separate runs, max abs difference: "
          f"{difference:.2g}")
    print(f"written per frame (motions, OpenPose JSON): {storage['bytes_per_frame'] / 1024:.1f} KiB in "
          f"{storage['files_per_frame']:.2f} files")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "batch.json").write_text(json.dumps(result, indent=2))
    print(f"wrote {args.out / 'batch.json'}")


if __name__ == "__main__":
    from jaxmocap.xla_options import configure_process

    configure_process()  # a command of the project: its process's settings before JAX starts
    main()
