"""Convergence of the fit at its defaults (issue 25): the share of frames whose solve meets its stopping rule within
N steps (`FitResult.converged`), with the median final reprojection error, on synthetic frames and on the real frames
of the shipped clips as a run observes them (our detector's keypoints, the run's IK start, its pinhole camera).

    python bench/convergence.py [--steps 20 100 200 400] [--x64] [--quick] [--out bench/results]
                                                            (or: jaxmocap bench --only convergence)

Real sets: every other frame of cam01 and cam03 of the single-person take and of each person of the two-person take
(each clip run once, `run_bodies` with an observer, in a temporary folder). Synthetic: 64 frames of
`jaxmocap.integrate.synthetic` (2 px noise, 15% of keypoints dropped, a perturbed start), weak perspective, and
`bench/fit.py`'s 1024 frames of the same kind ("synthetic 1024"). Each set is fitted once, at the largest N: a frame
converged within N steps is one that converged in at most N (`FitResult.steps`). For that N, the frames that did
not converge are counted as stalled (`levenberg_marquardt.stalled`: stopped short of the cap) or capped.
``--x64``: the same in float64 (the model loaded in float64). ``--quick``: the default cap alone
(`fitting.ITERATIONS`).
"""

from __future__ import annotations

import argparse
import json
import platform
import tempfile
from pathlib import Path

import jax
import numpy as np

ROOT = Path(__file__).resolve().parent.parent
CLIPS = {"cam01": ROOT / "jaxmocap/data/pose2sim_single_cam01.mp4",
         "cam03": ROOT / "tests/data/pose2sim_single_cam03.mp4",
         "two people": ROOT / "tests/data/pose2sim_multi_cam01.mp4"}


def observed_sets(model) -> dict[str, dict]:
    """Per clip and person: keypoints (N, 67, 3), the run's start (full pose, betas) and its lens, every other frame
    where the person was found."""
    from jaxmocap.integrate.fitting import full_pose_of
    from jaxmocap.motion import lens, read_motion
    from jaxmocap.pipeline.config import RunConfig
    from jaxmocap.pipeline.job import run_bodies
    from jaxmocap.pipeline.stages import initial_poses

    sets = {}
    for name, clip in CLIPS.items():
        parts: dict[int, list] = {}

        def observed(chunk, people, parts=parts):
            for pid, obs in people.items():
                start = initial_poses(model, obs)
                parts.setdefault(pid, []).append((obs.keypoints, np.asarray(full_pose_of(start)),
                                                  np.asarray(start.betas), obs.found))

        with tempfile.TemporaryDirectory() as work:
            report = run_bodies(RunConfig(str(clip), overlay=False, progress=False), work, observed=observed)
            run_lens = lens(read_motion(report.motion))  # the pinhole camera the run fitted through
        people = {pid: [np.concatenate(a) for a in zip(*chunks)] for pid, chunks in parts.items()}
        people = {pid: arrays for pid, arrays in people.items() if arrays[3].sum() >= 10}  # not passers-by
        for pid, (keypoints, pose, betas, found) in people.items():
            keep = np.flatnonzero(found)[::2]
            label = name if len(people) == 1 else f"{name} #{pid}"
            sets[label] = dict(keypoints=keypoints[keep], pose=pose[keep], betas=betas[keep], lens=run_lens)
    return sets


def main():
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, nargs="*", default=[20, 100, 200, 400])
    parser.add_argument("--x64", action="store_true")
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--out", type=Path, default=Path("bench/results"))
    args = parser.parse_args()
    if args.x64:
        jax.config.update("jax_enable_x64", True)

    import smplx_jax
    from jaxmocap.integrate import fit, synthetic
    from jaxmocap.integrate.fitting import ITERATIONS, params_from_full_pose

    if args.quick:
        args.steps = [ITERATIONS]
    dtype = np.float64 if args.x64 else np.float32
    model = smplx_jax.load_model(smplx_jax.default_model_path(), dtype=dtype)
    sets = observed_sets(smplx_jax.load_model(smplx_jax.default_model_path()) if args.x64 else model)
    cap = max(args.steps)
    results = {}
    for name, data in sets.items():
        init = params_from_full_pose(data["pose"].astype(dtype), data["betas"].astype(dtype), model.num_expression)
        focal, center = data["lens"]
        results[name] = fit(model, data["keypoints"].astype(dtype), init, focal_length=focal,
                            principal_point=np.asarray(center, dtype), iterations=cap)
    for name, frames, seed in (("synthetic", 64, 1), ("synthetic 1024", 1024, 1024)):
        problem = synthetic.make_problem(model, frames, seed=seed)
        results[name] = fit(model, problem.keypoints, problem.init, iterations=cap)
    rows = []
    for steps in args.steps:
        row = {"steps": steps}
        for name, result in results.items():
            converged = np.asarray(result.converged) & (np.asarray(result.steps) <= steps)
            row[name] = dict(frames=len(converged), converged=float(np.mean(converged)),
                             median_px=float(np.median(result.reprojection_error_px)))
        rows.append(row)
    ends = {}
    for name, result in results.items():
        left = ~np.asarray(result.converged)
        stalled = left & (np.asarray(result.steps) < cap)
        ends[name] = dict(stalled=np.flatnonzero(stalled).tolist(), capped=np.flatnonzero(left & ~stalled).tolist(),
                          steps_median=float(np.median(result.steps)), steps_p99=float(np.percentile(result.steps, 99)))
        print(f"{name}: steps median {ends[name]['steps_median']:.0f}, 99th percentile {ends[name]['steps_p99']:.0f}; "
              f"at {cap}, stalled {ends[name]['stalled']}, capped {ends[name]['capped']}", flush=True)

    names = list(results)
    print(f"\nshare converged at the defaults (median px), {np.dtype(dtype).name}, jax {jax.__version__}, "
          f"{platform.machine()}")
    print(f"{'steps':>6} " + " ".join(f"{n:>18}" for n in names))
    for row in rows:
        print(f"{row['steps']:>6} " + " ".join(f"{100 * row[n]['converged']:>10.0f}% ({row[n]['median_px']:4.2f})"
                                               for n in names))
    args.out.mkdir(parents=True, exist_ok=True)
    path = args.out / f"convergence{'_x64' if args.x64 else ''}.json"
    path.write_text(json.dumps(dict(benchmark="convergence", dtype=np.dtype(dtype).name, jax=jax.__version__,
                                    machine=platform.machine(), rows=rows, cap=cap, ends=ends), indent=2))
    print(f"wrote {path}")


if __name__ == "__main__":
    from jaxmocap.xla_options import configure_process

    configure_process()  # a command of the project: its process's settings before JAX starts
    main()
