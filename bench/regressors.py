"""Regressor speed: images/s of FrankMocap's hand and body networks (ResNet-50 + heads) in flax nnx, jitted, against
the same architecture in PyTorch (eager, no_grad), batch 1, 16 and 64, same machine, same run, same threads.
JAX runs in float32, in float32 with microbatches of 8 inside the compiled call, and with a bfloat16 encoder
(weights stored float32, heads float32); each output is compared with PyTorch's (max |diff|).

    python bench/regressors.py [--out bench/results] [--quick]      (or: jaxmocap bench --only regressors)

XLA CPU options are process-wide: compare them by running this script under different ``XLA_FLAGS``.
"""

import argparse
import json
import os
import pickle
import platform
import sys
import tempfile
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

GFLOP_PER_IMAGE = 8.2  # ResNet-50 at 224x224: 4.1 GMAC; the heads add < 0.1%
# matmul peaks measured on the machine of docs/BENCHMARKS.md ("Regressors"); elsewhere the shares are relative to them
PEAK_GFLOPS = {"torch f32": 186.0, "torch bf16": 532.0, "jax f32": 126.0}
_PEAK = {"torch_f32": "torch f32", "jax_f32": "jax f32", "jax_f32_mb8": "jax f32", "jax_bf16_mb8": "torch bf16"}


def _time(fns: dict, min_seconds: float, min_rounds: int) -> dict:
    """Seconds per call of each function: the best of interleaved rounds (one call of each per round), so load
    from other processes on a shared machine hits all variants alike and the best round is the least disturbed."""
    for fn in fns.values():
        fn()  # warm-up (compilation for JAX)
    times = {name: [] for name in fns}
    start = time.perf_counter()
    while len(times[next(iter(fns))]) < min_rounds or time.perf_counter() - start < min_seconds:
        for name, fn in fns.items():
            t0 = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - t0)
    return {name: min(t) for name, t in times.items()}


def _networks(tmp: Path):
    """Random reference networks in PyTorch, saved as FrankMocap's files and imported."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
    import torch

    import frankmocap_reference as ref
    from jaxmocap.regressors import convert_frankmocap

    rng = np.random.default_rng(0)
    mean_pose = rng.normal(0, 0.3, 48).astype(np.float32)
    (tmp / "mean.pkl").write_bytes(pickle.dumps({"mean_pose": mean_pose}))
    mean = np.concatenate([[5, 0, 0, 0, 0, 0], mean_pose[3:], np.zeros(10)]).astype(np.float32)
    hand = ref.randomize(ref.HandNet(mean), seed=1)
    body = ref.randomize(ref.HMR(np.tile([1.0, 0, 0, 1, 0, 0], 24), np.zeros(10), [0.9, 0, 0]), seed=2)
    torch.save(hand.state_dict(), tmp / "hand.pth")
    torch.save({"model": body.state_dict()}, tmp / "body.pt")
    convert_frankmocap(tmp / "hand.pth", tmp / "mean.pkl", tmp / "body.pt", tmp / "weights")
    return hand, body


def main():
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results"))
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--batches", type=int, nargs="*", default=[1, 16, 64])
    args = parser.parse_args()

    import torch

    import jaxmocap.regressors as R

    threads = os.cpu_count()
    torch.set_num_threads(threads)
    min_seconds, min_reps = (0.0, 2) if args.quick else (2.0, 3)
    with tempfile.TemporaryDirectory() as tmp:
        torch_nets = dict(zip(("hand", "body"), _networks(Path(tmp))))
        weights = Path(tmp) / "weights"
        jax_nets = {"jax f32": R.load(weights), "jax bf16": R.load(weights, dtype=jnp.bfloat16)}
    buckets = tuple(args.batches)
    predictors = {"jax_f32": R.Predictor(jax_nets["jax f32"], buckets, microbatch=max(buckets)),
                  "jax_f32_mb8": R.Predictor(jax_nets["jax f32"], buckets, microbatch=8),
                  "jax_bf16_mb8": R.Predictor(jax_nets["jax bf16"], buckets, microbatch=8)}

    rows = [_row(kind, batch, torch_nets[kind], predictors, min_seconds, min_reps)
            for kind in ("hand", "body") for batch in args.batches]
    _print_table(rows, f"\nregressors (ResNet-50 + head), {threads} threads, "
                 f"{platform.processor() or platform.machine()}, jax {jax.__version__}, torch {torch.__version__}, "
                 f"XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}")
    args.out.mkdir(parents=True, exist_ok=True)
    result = dict(benchmark="regressors", threads=threads, machine=platform.machine(), jax=jax.__version__,
                  torch=torch.__version__, xla_flags=os.environ.get("XLA_FLAGS", ""), gflop_per_image=GFLOP_PER_IMAGE,
                  matmul_peak_gflops=PEAK_GFLOPS, devices=[str(d) for d in jax.devices()], rows=rows)
    (args.out / "regressors.json").write_text(json.dumps(result, indent=2))
    print(f"wrote {args.out / 'regressors.json'}")


def _row(kind: str, batch: int, torch_net, predictors: dict, min_seconds: float, min_reps: int) -> dict:
    """Images/s of the PyTorch network and of each JAX predictor on one random batch, and each JAX output's max
    |diff| to PyTorch's."""
    import torch

    x = np.random.default_rng(batch).normal(0, 1, (batch, 224, 224, 3)).astype(np.float32)
    xj = jnp.asarray(x)
    nchw = torch.from_numpy(x).permute(0, 3, 1, 2).contiguous()

    def run_torch():
        with torch.no_grad():
            return torch_net(nchw)

    reference = run_torch()
    reference = (reference[0] if isinstance(reference, tuple) else reference).numpy()  # body: rotmats
    fns = {"torch_f32": run_torch}
    row = dict(network=kind, batch=batch)
    for name, predictor in predictors.items():
        fn = getattr(predictor, kind)
        out = fn(xj)
        out = out[0] if isinstance(out, tuple) else out
        row[f"{name}_max_abs_diff"] = float(np.abs(np.asarray(out) - reference).max())
        fns[name] = lambda f=fn: jax.block_until_ready(f(xj))
    row.update({name: batch / seconds for name, seconds in _time(fns, min_seconds, min_reps).items()})
    print(f"{kind} {batch}: " + ", ".join(f"{k} {row[k]:.2f}" for k in fns), flush=True)
    return row


def _print_table(rows: list[dict], title: str) -> None:
    print(title)
    names = ["torch_f32", "jax_f32", "jax_f32_mb8", "jax_bf16_mb8"]
    print(f"{'net':>5} {'batch':>5} " + " ".join(f"{n + ' img/s':>18}" for n in names) + "   best jax / torch")
    for r in rows:
        best = max(names[1:3], key=lambda n: r[n])
        print(f"{r['network']:>5} {r['batch']:>5} " + " ".join(f"{r[n]:>18.2f}" for n in names)
              + f"   {r[best] / r['torch_f32']:.2f}x ({best})")
    peaks = ", ".join(f"{name} {value:.0f}" for name, value in PEAK_GFLOPS.items())
    print(f"GFLOP/s (share of the matmul peak: {peaks}); max |diff| to torch")
    for r in rows:
        print(f"{r['network']:>5} {r['batch']:>5} " + " ".join(
            f"{n}: {r[n] * GFLOP_PER_IMAGE:.0f} ({r[n] * GFLOP_PER_IMAGE / PEAK_GFLOPS[_PEAK[n]]:.0%})" for n in names)
            + "  |d| " + " ".join(f"{r[n + '_max_abs_diff']:.1e}" for n in names[1:]))


if __name__ == "__main__":
    from jaxmocap.xla_options import configure_process

    configure_process()  # a command of the project: its process's settings before JAX starts
    main()
