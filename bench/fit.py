"""Optimization integration speed: frames/s of the fit (`jaxmocap.integrate.fit`, optimistix) over 256 and 1024
frames and its final reprojection error, in two settings: live capture's (`jaxmocap.pipeline.stages.FIT_FROM_IK`,
CG steps, 20 iterations) and the defaults (dense steps, at most `fitting.ITERATIONS`, stopping once converged: the
share converged is reported), against a PyTorch baseline on the same objective, data, start and
threads: the ``smplx`` package + ``torch.optim.LBFGS`` (strong Wolfe line search, 20 iterations) and Adam (20 steps).
(The comparison with the hand-written Levenberg-Marquardt that the optimistix fit replaced is in docs/BENCHMARKS.md,
measured by this script at commit 990c816.)

    python bench/fit.py [--out bench/results] [--quick]      (or: jaxmocap bench --only fit)

Data: synthetic frames with known answers (random plausible whole-body poses, both hands, 2 px noise, 15% of
keypoints dropped, a start perturbed from the truth: `jaxmocap.integrate.synthetic`), default body model.
The objective is the fit's: Cauchy-robust confidence-weighted reprojection of the 67 OpenPose keypoints + the
same priors (pose near the start, shape L2, elbow/knee bending limits). For PyTorch the camera is parametrised as
``scale0 * exp(a)`` and ``trans0 + scale0 * b`` and the cost divided by ``scale0^2`` so that all unknowns are
O(1). The camera start is the same for both (fitted to the start pose's keypoints). --quick: PyTorch at 256 only.
"""

import argparse
import dataclasses
import json
import os
import platform
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np


def torch_fit(model_dir, problem, cam0, config, method, iterations, threads):
    """The PyTorch baseline: seconds, fitted `SMPLXParams`, camera scale and translation."""
    import torch

    torch.set_num_threads(threads)
    cost, unknowns, camera = _torch_objective(model_dir, problem, cam0, config)
    begin = time.perf_counter()
    _minimize(cost, unknowns, method, iterations)
    seconds = time.perf_counter() - begin
    scale, trans = (a.detach().numpy() for a in camera())
    return seconds, _params_of(unknowns), scale, trans


def _torch_objective(model_dir, problem, cam0, config):
    """The fit's cost in PyTorch (``smplx`` forward); its unknowns (the pose tensors by name, then the camera's
    ``log_s``, ``d_t``); the camera ``(scale, trans)`` they give, ``scale0 * exp(log_s)`` and ``trans0 + scale0 *
    d_t`` about the start camera ``cam0`` (so that all unknowns are O(1))."""
    import smplx
    import torch

    from jaxmocap.integrate.least_squares import BEND_LIMITS, bend_weights
    from smplx_jax import constants

    init = problem.init
    b = init.betas.shape[0]
    body = smplx.create(str(model_dir), model_type="smplx", use_pca=False, flat_hand_mean=True, batch_size=b)

    def t(a):
        return torch.tensor(np.asarray(a), dtype=torch.float32).reshape(b, -1)

    start = dict(global_orient=t(init.global_orient), body_pose=t(init.body_pose),
                 left_hand_pose=t(init.left_hand_pose), right_hand_pose=t(init.right_hand_pose), betas=t(init.betas))
    var = {k: v.clone().requires_grad_(True) for k, v in start.items()}
    s0, t0 = torch.tensor(np.asarray(cam0[:, 0])), torch.tensor(np.asarray(cam0[:, 1:]))
    log_s, d_t = torch.zeros(b, requires_grad=True), torch.zeros(b, 2, requires_grad=True)

    def camera():
        return s0 * torch.exp(log_s), t0 + s0[:, None] * d_t

    kp = torch.tensor(problem.keypoints)
    conf = kp[..., 2]
    index = list(constants.OPENPOSE67_FROM_SMPLX)
    sigma2 = (config.robust_scale * s0) ** 2
    prior = {"global_orient": config.prior_global, "body_pose": config.prior_body,
             "left_hand_pose": config.prior_hand, "right_hand_pose": config.prior_hand}
    jaw = torch.zeros(b, 3)

    def cost():
        out = body(**var, jaw_pose=jaw, return_verts=True)
        x = out.joints[:, index, :2]
        scale, trans = camera()
        pix = scale[:, None, None] * x + trans[:, None, :]
        r2 = ((pix - kp[..., :2]) ** 2).sum(-1)
        data = (conf * sigma2[:, None] * torch.log1p(r2 / sigma2[:, None])).sum(1)
        reg = sum((s0 * w) ** 2 * ((var[k] - start[k]) ** 2).sum(1) for k, w in prior.items())
        reg = reg + (s0 * config.prior_betas) ** 2 * (var["betas"] ** 2).sum(1)
        pose = torch.cat([var["global_orient"], var["body_pose"], jaw, jaw, jaw, var["left_hand_pose"],
                          var["right_hand_pose"]], 1).reshape(b, 55, 3)  # SMPL-X's joint order
        for (j, c, sign, slack), weight in zip(BEND_LIMITS, bend_weights(config)):
            reg = reg + (s0 * weight) ** 2 * torch.relu(sign * pose[:, j, c] - slack) ** 2
        return (0.5 * (data + reg) / s0**2).sum()

    return cost, list(var.values()) + [log_s, d_t], camera


def _minimize(cost, params, method: str, iterations: int) -> None:
    """``iterations`` of L-BFGS (strong Wolfe) or Adam on ``cost()`` over the tensors ``params``."""
    import torch

    if method == "lbfgs":
        opt = torch.optim.LBFGS(params, lr=1.0, max_iter=iterations, line_search_fn="strong_wolfe")

        def closure():
            opt.zero_grad()
            loss = cost()
            loss.backward()
            return loss

        opt.step(closure)
    else:
        opt = torch.optim.Adam(params, lr=0.02)
        for _ in range(iterations):
            opt.zero_grad()
            loss = cost()
            loss.backward()
            opt.step()


def _params_of(unknowns):
    """Batched `SMPLXParams` of the fitted unknowns of `_torch_objective` (jaw, eyes, expression, translation 0)."""
    from smplx_jax import SMPLXParams

    orient, body, left, right, betas = (jnp.asarray(v.detach().numpy()) for v in unknowns[:5])
    b = len(betas)
    zeros = jnp.zeros((b, 3))
    return SMPLXParams(orient, body.reshape(b, 21, 3), left.reshape(b, 15, 3), right.reshape(b, 15, 3), zeros, zeros,
                       zeros, betas, jnp.zeros((b, 10)), zeros)


def main():
    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results"))
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--frames", type=int, nargs="*", default=[256, 1024])
    args = parser.parse_args()

    import torch

    import smplx_jax
    from jaxmocap.integrate import fitting, reprojection_errors, synthetic
    from jaxmocap.integrate.camera import weak_perspective_from_points
    from jaxmocap.integrate.keypoints import keypoints_cm

    threads = os.cpu_count()
    path = smplx_jax.default_model_path()
    model = smplx_jax.load_model(path)
    km = fitting.openpose_keypoint_model(model)
    from jaxmocap.pipeline.stages import FIT_FROM_IK

    config = fitting.FitConfig()  # the objective PyTorch minimises, for as many steps as the pipeline takes
    iterations = FIT_FROM_IK.iterations
    settings = {"pipeline": FIT_FROM_IK, "defaults": dataclasses.replace(config, iterations=fitting.ITERATIONS)}

    @jax.jit
    @jax.vmap
    def start_camera(theta, betas, kp):
        s, t = weak_perspective_from_points(keypoints_cm(km, theta, betas)[:2].T, kp[:, :2], kp[:, 2])
        return jnp.concatenate([s[None], t])

    rows = []
    for frames in args.frames:
        problem = synthetic.make_problem(model, frames, seed=frames)
        cam0 = np.asarray(start_camera(fitting.full_pose_of(problem.init), problem.init.betas,
                                       jnp.asarray(problem.keypoints)))

        def err(p, s, t, problem=problem):
            return float(np.median(reprojection_errors(model, p, s, t, problem.keypoints)))

        row = {"frames": frames}
        for name, setting in settings.items():
            row.update({f"{name}_{key}": value for key, value in
                        _jax_row(model, problem, cam0, setting, 3 if args.quick else 5, err).items()})
        if not (args.quick and frames > 256):
            for method in ("lbfgs", "adam"):
                secs, params, s, t = torch_fit(path.parent.parent, problem, cam0, config, method, iterations, threads)
                row[f"torch_{method}_fps"] = frames / secs
                row[f"torch_{method}_error_px"] = err(params, s, t)
                row[f"speedup_vs_{method}"] = secs / row["pipeline_seconds"]
        rows.append(row)
        print(row, flush=True)

    _print_table(rows, f"\nfit (pipeline and PyTorch {iterations} iterations, defaults at most "
                 f"{fitting.ITERATIONS}), float32, {threads} threads, "
                 f"{platform.processor() or platform.machine()}, jax {jax.__version__}, torch {torch.__version__}; "
                 "median final reprojection error in px")
    args.out.mkdir(parents=True, exist_ok=True)
    result = dict(benchmark="fit", threads=threads, machine=platform.machine(), jax=jax.__version__,
                  torch=torch.__version__, devices=[str(d) for d in jax.devices()],
                  settings={name: vars(setting) for name, setting in settings.items()}, rows=rows)
    (args.out / "fit.json").write_text(json.dumps(result, indent=2))
    print(f"wrote {args.out / 'fit.json'}")


def _jax_row(model, problem, cam0, config, repeats: int, err) -> dict:
    """Times of `fitting.fit` with ``config`` on ``problem`` from the camera ``cam0``: its first call (compilation
    included) and the best of ``repeats``, with the start's and the fit's reprojection errors ``err(params, scale,
    trans)`` and the share of frames converged."""
    from jaxmocap.integrate import fitting

    def run():
        return jax.block_until_ready(fitting.fit(model, problem.keypoints, problem.init, cam0[:, 0], cam0[:, 1:],
                                                 iterations=config.iterations, config=config))

    begin = time.perf_counter()
    run()
    first_call = time.perf_counter() - begin
    times = []
    for _ in range(repeats):
        begin = time.perf_counter()
        result = run()
        times.append(time.perf_counter() - begin)
    seconds, frames = min(times), len(problem.keypoints)
    return dict(seconds=seconds, fps=frames / seconds, first_call_seconds=first_call,
                start_error_px=err(problem.init, cam0[:, 0], cam0[:, 1:]),
                error_px=err(result.params, result.camera_scale, result.camera_trans),
                converged=float(np.mean(result.converged)))


def _print_table(rows: list[dict], title: str) -> None:
    print(title)
    print(f"{'frames':>6} {'start px':>9} {'pipe fps':>9} {'pipe px':>8} {'default fps':>12} {'default px':>11} "
          f"{'converged':>10} {'LBFGS fps':>10} {'LBFGS px':>9} {'ratio':>7} {'Adam fps':>9} {'Adam px':>8} "
          f"{'ratio':>7}")
    for r in rows:
        torch_cols = (f"{r['torch_lbfgs_fps']:>10.1f} {r['torch_lbfgs_error_px']:>9.2f} "
                      f"{r['speedup_vs_lbfgs']:>6.1f}x "
                      f"{r['torch_adam_fps']:>9.1f} {r['torch_adam_error_px']:>8.2f} {r['speedup_vs_adam']:>6.1f}x"
                      if "torch_lbfgs_fps" in r else f"{'-':>10} {'-':>9} {'-':>7} {'-':>9} {'-':>8} {'-':>7}")
        print(f"{r['frames']:>6} {r['pipeline_start_error_px']:>9.2f} {r['pipeline_fps']:>9.1f} "
              f"{r['pipeline_error_px']:>8.2f} {r['defaults_fps']:>12.1f} {r['defaults_error_px']:>11.2f} "
              f"{100 * r['defaults_converged']:>9.0f}% {torch_cols}")


if __name__ == "__main__":
    main()
