"""End-to-end speed of ``jaxmocap run`` (embedded default path) on the bundled clip, with a per-stage breakdown.

    python bench/pipeline.py [--out bench/results] [--quick]      (or: jaxmocap bench --only pipeline)

The clip is run twice in one process: the first run includes JAX compilation (what a first ``jaxmocap demo``
costs); the second is the steady state. Overlay rendering and exports are timed as stages of their own.
"""

import argparse
import json
import os
import platform
import tempfile
from pathlib import Path

CLIP = Path(__file__).resolve().parents[1] / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results"))
    parser.add_argument("--quick", action="store_true", help="one run (compilation included)")
    args = parser.parse_args()

    from jaxmocap.pipeline import run

    rows = []
    for name in ("first run (compiles)",) + (() if args.quick else ("steady state",)):
        with tempfile.TemporaryDirectory() as tmp:
            report = run(CLIP, tmp, exports=("bvh", "gltf"), progress=False)
        seconds = dict(report.seconds)
        total = sum(seconds.values())
        rows.append(dict(run=name, frames=report.frames, seconds=total, fps=report.frames / total, stages=seconds))

    stages = list(rows[0]["stages"])
    print(f"\njaxmocap run, {CLIP.name} (1080x1920, {rows[0]['frames']} frames), {os.cpu_count()} CPUs, "
          f"{platform.machine()}")
    print(f"{'':<22}{'frames/s':>9}{'total s':>9}" + "".join(f"{s:>14}" for s in stages))
    for r in rows:
        print(f"{r['run']:<22}{r['fps']:>9.1f}{r['seconds']:>9.1f}" + "".join(
            f"{r['stages'].get(s, 0.0) * 1000 / r['frames']:>11.1f} ms" for s in stages))
    print("(stage columns: milliseconds per frame)")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "pipeline.json").write_text(json.dumps(dict(benchmark="pipeline", cpus=os.cpu_count(), rows=rows),
                                                       indent=2))
    print(f"wrote {args.out / 'pipeline.json'}")


if __name__ == "__main__":
    main()
