"""End-to-end speed of ``jaxmocap run`` on the bundled clip, with a per-stage breakdown: the embedded default
path (BlazePose heavy), the same with BlazePose full (``--landmarks full``), with ``--mode body`` (no hand model),
on Pose2Sim's two-person take (both people tracked and fitted), and the FrankMocap path (regressors with random
weights of the real architecture, copy-and-paste).

    python bench/pipeline.py [--out bench/results] [--quick]      (or: jaxmocap bench --only pipeline)

Each path runs twice in one process: the first run includes JAX compilation (what a first ``jaxmocap demo``
costs); the second is the steady state (``--quick``: first runs only). Overlay rendering and exports are timed
as stages of their own.
"""

import argparse
import json
import os
import platform
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLIP = ROOT / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"
TWO_PEOPLE = ROOT / "tests" / "data" / "pose2sim_multi_cam01.mp4"


def main():
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results"))
    parser.add_argument("--quick", action="store_true", help="one run (compilation included)")
    args = parser.parse_args()

    from flax import nnx

    from jaxmocap.pipeline import RunConfig, run
    from jaxmocap.regressors import BodyRegressor, HandRegressor, Regressors, initialised
    from jaxmocap.regressors.weights import save

    rows = []
    with tempfile.TemporaryDirectory() as weights:
        networks = Regressors(initialised(lambda: HandRegressor(rngs=nnx.Rngs(0))),
                              initialised(lambda: BodyRegressor(rngs=nnx.Rngs(1))))
        save(Path(weights), networks, {})
        for path, clip, options in (("default (heavy)", CLIP, {}), ("landmarks full", CLIP, dict(landmarks="full")),
                                    ("body only", CLIP, dict(mode="body")),
                                    ("two people", TWO_PEOPLE, {}),
                                    ("regressors", CLIP, dict(weights=weights, integration="copy-paste"))):
            for name in ("first run",) + (() if args.quick else ("steady",)):
                with tempfile.TemporaryDirectory() as tmp:
                    report = run(RunConfig(clip, exports=("bvh", "gltf"), progress=False, **options), tmp)
                seconds = dict(report.seconds)
                total = sum(seconds.values())
                rows.append(dict(run=f"{path}, {name}", frames=report.frames, people=len(report.people),
                                 seconds=total, fps=report.frames / total, stages=seconds))

    stages = list(dict.fromkeys(s for r in rows for s in r["stages"]))
    print(f"\njaxmocap run, {CLIP.name} and {TWO_PEOPLE.name} ({rows[0]['frames']} frames each), "
          f"{os.cpu_count()} CPUs, {platform.machine()}")
    print(f"{'':<28}{'people':>7}{'frames/s':>9}{'total s':>9}" + "".join(f"{s:>18}" for s in stages))
    for r in rows:
        print(f"{r['run']:<28}{r['people']:>7}{r['fps']:>9.1f}{r['seconds']:>9.1f}" + "".join(
            f"{r['stages'].get(s, 0.0) * 1000 / r['frames']:>15.1f} ms" for s in stages))
    print("(stage columns: milliseconds per frame)")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "pipeline.json").write_text(json.dumps(dict(benchmark="pipeline", cpus=os.cpu_count(), rows=rows),
                                                       indent=2))
    print(f"wrote {args.out / 'pipeline.json'}")


if __name__ == "__main__":
    from jaxmocap.xla_options import configure_process

    configure_process()  # a command of the project: its process's settings before JAX starts
    main()
