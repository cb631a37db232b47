"""Body model speed: frames/s of smplx_jax's full forward and joints-only path against the PyTorch ``smplx``
package's forward, batch 1, 64 and 1024, float32, on the default model, same machine, same run, same threads.

    python bench/body_model.py [--out bench/results] [--quick]      (or: jaxmocap bench --only body_model)
"""

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import jax
import numpy as np


def _time(fn, min_seconds, min_reps=3):
    fn()  # warm-up (compilation for JAX)
    fn()
    times = []
    start = time.perf_counter()
    while len(times) < min_reps or time.perf_counter() - start < min_seconds:
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results"))
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--batches", type=int, nargs="*", default=[1, 64, 1024])
    args = parser.parse_args()

    import smplx
    import torch

    import smplx_jax
    from smplx_jax.default_model import default_model_path

    threads = os.cpu_count()
    torch.set_num_threads(threads)
    path = default_model_path()
    model = smplx_jax.load_model(path)
    full = jax.jit(jax.vmap(smplx_jax.forward, in_axes=(None, 0)))
    joints = jax.jit(jax.vmap(smplx_jax.forward_joints, in_axes=(None, 0)))
    min_seconds = 0.5 if args.quick else 2.0

    rows = []
    for batch in args.batches:
        rng = np.random.default_rng(batch)
        pose = rng.normal(0, 0.5, (batch, 55, 3)).astype(np.float32)
        betas = rng.normal(0, 1, (batch, 10)).astype(np.float32)
        fields = dict(
            global_orient=pose[:, 0], body_pose=pose[:, 1:22], jaw_pose=pose[:, 22], leye_pose=pose[:, 23],
            reye_pose=pose[:, 24], left_hand_pose=pose[:, 25:40], right_hand_pose=pose[:, 40:55], betas=betas,
            expression=np.zeros((batch, 10), np.float32), transl=np.zeros((batch, 3), np.float32))
        params = smplx_jax.SMPLXParams(**{k: jax.numpy.asarray(v) for k, v in fields.items()})
        t_full = _time(lambda: jax.block_until_ready(full(model, params)), min_seconds)
        t_joints = _time(lambda: jax.block_until_ready(joints(model, params)), min_seconds)

        torch_model = smplx.create(str(path.parent.parent), model_type="smplx", use_pca=False, flat_hand_mean=True,
                                   batch_size=batch)
        tp = {k: torch.from_numpy(np.ascontiguousarray(v).reshape(batch, -1)) for k, v in fields.items()}

        def torch_forward():
            with torch.no_grad():
                return torch_model(**tp, return_verts=True)

        t_torch = _time(torch_forward, min_seconds)
        rows.append(dict(batch=batch, jax_full_fps=batch / t_full, jax_joints_fps=batch / t_joints,
                         torch_full_fps=batch / t_torch, full_ratio=t_torch / t_full, joints_ratio=t_torch / t_joints))

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
    main()
