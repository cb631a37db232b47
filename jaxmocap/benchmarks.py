"""``jaxmocap bench``: runs the scripts in the source checkout's ``bench/`` folder."""

import runpy
import sys
from pathlib import Path

from jaxmocap.errors import InputError

BENCH_DIR = Path(__file__).resolve().parents[1] / "bench"


def available() -> list[str]:
    """The benchmarks of the source checkout's ``bench/`` folder, by name."""
    return sorted(p.stem for p in BENCH_DIR.glob("*.py") if not p.stem.startswith("_"))


def run_benchmarks(names, out_dir: Path, quick: bool = False) -> None:
    """Run the benchmarks ``names`` (all when empty) one after another in this process, each writing its
    JSON into ``out_dir``; `InputError` without a ``bench/`` folder or for an unknown name."""
    if not BENCH_DIR.is_dir():
        raise InputError(f"no bench/ folder beside the package ({BENCH_DIR}): benchmarks run from a source checkout")
    names = names or available()
    unknown = sorted(set(names) - set(available()))
    if unknown:
        raise InputError(f"unknown benchmark(s) {', '.join(unknown)}; available: {', '.join(available())}")
    for name in names:
        argv = [str(BENCH_DIR / f"{name}.py"), "--out", str(out_dir)] + (["--quick"] if quick else [])
        saved, sys.argv = sys.argv, argv
        try:
            runpy.run_path(argv[0], run_name="__main__")
        finally:
            sys.argv = saved
