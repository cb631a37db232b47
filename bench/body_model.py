"""Body model speed: frames/s of smplx_jax's full forward and joints-only path against the PyTorch ``smplx``
package's forward, batch 1, 64 and 1024, float32, same machine, same run, same threads. The model file is the
default model with random pose correctives (its own are zero; a real file's are dense), so that nothing is
faster for zeros. The three are timed in rounds, each at its steady state, so that all see the same
machine load.

    python bench/body_model.py [--out bench/results] [--quick]      (or: jaxmocap bench --only body_model)
"""

import argparse
import json
import os
import platform
import statistics
import tempfile
import time
from pathlib import Path

import jax
import numpy as np


def _time_in_rounds(fns, min_seconds, block_seconds=0.3, warm_seconds=0.1, min_rounds=3):
    """Median seconds per call of each function at its steady state. In each round every function runs back to
    back: calls for ``warm_seconds`` untimed (a call right after another workload or a pause runs slower:
    threads and caches are cold; docs/BENCHMARKS.md, "Body model"), then timed calls for ``block_seconds``; rounds
    repeat so that all see the same machine load."""
    for fn in fns:  # compilation for JAX
        fn()
    times = [[] for _ in fns]
    start = time.perf_counter()
    rounds = 0
    while rounds < min_rounds or time.perf_counter() - start < min_seconds:
        for fn, fn_times in zip(fns, times):
            for seconds, record in ((warm_seconds, False), (block_seconds, True)):
                block_start = time.perf_counter()
                while True:
                    t0 = time.perf_counter()
                    fn()
                    if record:
                        fn_times.append(time.perf_counter() - t0)
                    if time.perf_counter() - block_start >= seconds:
                        break
        rounds += 1
    return [statistics.median(t) for t in times]


def _model_file(folder: Path) -> Path:
    """The default model with random pose correctives, as ``folder/smplx/SMPLX_NEUTRAL.npz``."""
    from smplx_jax.default_model import default_model_path

    arrays = dict(np.load(default_model_path()))
    arrays["posedirs"] = np.random.default_rng(0).normal(0, 1e-3, arrays["posedirs"].shape)
    path = folder / "smplx" / "SMPLX_NEUTRAL.npz"
    path.parent.mkdir(parents=True)
    np.savez(path, **arrays)
    return path


def _measure(path: Path, batch: int, min_seconds: float) -> dict:
    """One row of the table: frames/s of the three forwards on random bodies."""
    import smplx
    import torch

    import smplx_jax

    model = smplx_jax.load_model(path)
    full = jax.jit(jax.vmap(smplx_jax.forward, in_axes=(None, 0)))
    joints = jax.jit(jax.vmap(smplx_jax.forward_joints, in_axes=(None, 0)))
    rng = np.random.default_rng(batch)
    pose = rng.normal(0, 0.5, (batch, 55, 3)).astype(np.float32)
    betas = rng.normal(0, 1, (batch, 10)).astype(np.float32)
    fields = dict(
        global_orient=pose[:, 0], body_pose=pose[:, 1:22], jaw_pose=pose[:, 22], leye_pose=pose[:, 23],
        reye_pose=pose[:, 24], left_hand_pose=pose[:, 25:40], right_hand_pose=pose[:, 40:55], betas=betas,
        expression=np.zeros((batch, 10), np.float32), transl=np.zeros((batch, 3), np.float32))
    params = smplx_jax.SMPLXParams(**{k: jax.numpy.asarray(v) for k, v in fields.items()})
    torch_model = smplx.create(str(path.parent.parent), model_type="smplx", use_pca=False, flat_hand_mean=True,
                               batch_size=batch)
    tp = {k: torch.from_numpy(np.ascontiguousarray(v).reshape(batch, -1)) for k, v in fields.items()}

    def torch_forward():
        with torch.no_grad():
            return torch_model(**tp, return_verts=True)

    t_full, t_joints, t_torch = _time_in_rounds(
        [lambda: jax.block_until_ready(full(model, params)), lambda: jax.block_until_ready(joints(model, params)),
         torch_forward], min_seconds)
    return dict(batch=batch, jax_full_fps=batch / t_full, jax_joints_fps=batch / t_joints,
                torch_full_fps=batch / t_torch, full_ratio=t_torch / t_full, joints_ratio=t_torch / t_joints)


def main():
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results"))
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--batches", type=int, nargs="*", default=[1, 64, 1024])
    args = parser.parse_args()

    import torch

    threads = os.cpu_count()
    torch.set_num_threads(threads)
    with tempfile.TemporaryDirectory() as folder:
        path = _model_file(Path(folder))
        rows = [_measure(path, batch, 0.5 if args.quick else 2.0) for batch in args.batches]

    print(f"\nbody model, float32, {threads} threads, {platform.processor() or platform.machine()}, "
          f"jax {jax.__version__}, torch {torch.__version__}")
    print(f"{'batch':>6} {'smplx-torch fps':>16} {'jax full fps':>13} {'ratio':>7} {'jax joints fps':>15} {'ratio':>8}")
    for r in rows:
        print(f"{r['batch']:>6} {r['torch_full_fps']:>16.1f} {r['jax_full_fps']:>13.1f} {r['full_ratio']:>6.2f}x "
              f"{r['jax_joints_fps']:>15.1f} {r['joints_ratio']:>7.1f}x")
    args.out.mkdir(parents=True, exist_ok=True)
    result = dict(benchmark="body_model", threads=threads, machine=platform.machine(), jax=jax.__version__,
                  torch=torch.__version__, devices=[str(d) for d in jax.devices()], rows=rows)
    (args.out / "body_model.json").write_text(json.dumps(result, indent=2))
    print(f"wrote {args.out / 'body_model.json'}")


if __name__ == "__main__":
    from jaxmocap.xla_options import configure_process

    configure_process()  # a command of the project: its process's settings before JAX starts
    main()
