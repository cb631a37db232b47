"""Optimization integration speed: frames/s of the fit (`jaxmocap.integrate.fit`, optimistix) over 256 and 1024 frames
and its final reprojection error, in two settings: from a start IK gave (`CG_FROM_IK`: CG steps, 20 iterations; live
capture's fit until its window of the clip fit) and the defaults (dense steps, at most `fitting.ITERATIONS`, stopping
once converged: the share converged is reported), against a PyTorch baseline on the same objective, data, start and
threads: the ``smplx`` package + ``torch.optim.LBFGS`` (strong Wolfe line search, 20 iterations) and Adam (20 steps).
(The comparison with the hand-written Levenberg-Marquardt that the optimistix fit replaced is in docs/BENCHMARKS.md,
measured by this script at commit 990c816.)

    python bench/fit.py [--out bench/results] [--quick] [--parts frames clip]      (or: jaxmocap bench --only fit)

Data: synthetic frames with known answers (random plausible whole-body poses, both hands, 2 px noise, 15% of
keypoints dropped, a start perturbed from the truth: `jaxmocap.integrate.synthetic`), default body model.
The objective is the fit's: Cauchy-robust confidence-weighted reprojection of the 67 OpenPose keypoints + the
same priors (pose near the start, shape L2, elbow/knee bending limits). For PyTorch the camera is parametrised as
``scale0 * exp(a)`` and ``trans0 + scale0 * b`` and the cost divided by ``scale0^2`` so that all unknowns are
O(1). The camera start is the same for both (fitted to the start pose's keypoints). --quick: PyTorch at 256 only.

``--parts clip``: ``jaxmocap fit``'s clip fit (`fit_folder.fitted_keypoints`: one shape, the motion, windows) on a
synthetic clip of 256 and 1024 frames (`synthetic.make_clip`: 2 px noise, 15% of keypoints dropped, a pinhole
camera) from the start the keypoints give (`keypoint_start.facing_pose`), against the per-frame fit it replaced
(`fitting.fit` at its defaults, same start, same camera): frames/s once compiled, the share of frames converged,
the median reprojection error and the body keypoints' error in 3D after a similarity per frame (PA, mm).
"""

import argparse
import dataclasses
import json
import os
import platform
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

# The per-frame fit from a start that IK gave, with conjugate-gradient steps: the start holds BlazePose's 3D (depth,
# twists) that the 2D keypoints do not see, so the prior keeps the fit near it (0.1 m/rad).
CG_FROM_IK = dict(prior_body=0.1, prior_finger_hinge=0.05, prior_finger_range=0.2, linear_solver="cg")


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
    parser.add_argument("--parts", nargs="+", choices=("frames", "clip"), default=["frames", "clip"])
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if "clip" in args.parts:
        clip_benchmark(args.frames, args.out, 1 if args.quick else 2)
    if "frames" in args.parts:
        frames_benchmark(args)


def clip_benchmark(sizes: list[int], out: Path, repeats: int) -> None:
    """``--parts clip`` (module docstring): prints a table and writes ``out/fit_clip.json``."""
    import smplx_jax
    from jaxmocap.integrate import fitting, synthetic
    from jaxmocap.integrate.clip import points_3d
    from jaxmocap.pipeline.fit_folder import facing_params, fitted_keypoints

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    from train.metrics import pa_mpjpe

    model = smplx_jax.load_model(smplx_jax.default_model_path())
    km = fitting.openpose_keypoint_model(model)
    focal, centre = 1500.0, np.asarray([960.0, 540.0], np.float32)
    body = jax.jit(jax.vmap(lambda pose, betas: points_3d(km, pose, betas, jnp.zeros(3))[:25]))

    def pa_mm(params, clip):
        """Median over frames of the body keypoints' mean error after a similarity, mm."""
        ours = np.asarray(body(fitting.full_pose_of(params), params.betas), np.float64)
        truth = np.asarray(body(jnp.asarray(clip.pose, jnp.float32), jnp.broadcast_to(
            jnp.asarray(clip.betas, jnp.float32), (len(clip.pose), model.num_betas))), np.float64)
        return 1000 * float(np.median(pa_mpjpe(ours, truth, np.ones(ours.shape[:2], bool))))

    def timed(run):
        begin = time.perf_counter()
        result = run()
        first = time.perf_counter() - begin
        best = first
        for _ in range(repeats):
            begin = time.perf_counter()
            result = run()
            best = min(best, time.perf_counter() - begin)
        return result, first, best

    rows = []
    for frames in sizes:
        clip = synthetic.make_clip(model, frames, seed=frames, focal_length=focal, principal_point=centre)
        rng = np.random.default_rng(frames)
        keypoints = clip.keypoints.copy()
        keypoints[..., :2] += rng.normal(scale=2.0, size=keypoints[..., :2].shape)
        keypoints[rng.uniform(size=keypoints.shape[:2]) < 0.15] = 0.0
        keypoints = keypoints.astype(np.float32)
        fitted, first, best = timed(lambda: jax.block_until_ready(
            fitted_keypoints(model, keypoints, (focal, centre), 30.0)))
        row = dict(frames=frames, clip_fps=frames / best, clip_first_call_seconds=first,
                   clip_converged=float(np.mean(fitted.converged)),
                   clip_error_px=float(np.median(np.asarray(fitting_errors(model, fitted.bodies, keypoints,
                                                                           (focal, centre))))),
                   clip_pa_mm=pa_mm(fitted.bodies.params, clip))
        start = facing_params(model, keypoints)
        per_frame, first, best = timed(lambda: jax.block_until_ready(fitting.fit(
            model, keypoints, start, focal_length=focal, principal_point=centre)))
        row.update(frame_fps=frames / best, frame_first_call_seconds=first,
                   frame_converged=float(np.mean(per_frame.converged)),
                   frame_error_px=float(np.median(np.asarray(per_frame.reprojection_error_px))),
                   frame_pa_mm=pa_mm(per_frame.params, clip))
        row["speedup"] = row["clip_fps"] / row["frame_fps"]
        rows.append(row)
        print(row, flush=True)
    print(f"\njaxmocap fit: the clip fit against the per-frame fit (defaults), {os.cpu_count()} threads, "
          f"{platform.processor() or platform.machine()}, {jax.devices()[0].platform}, jax {jax.__version__}")
    print(f"{'frames':>6} {'clip fps':>9} {'converged':>10} {'px':>6} {'PA mm':>6} {'frame fps':>10} "
          f"{'converged':>10} {'px':>6} {'PA mm':>6} {'ratio':>6}")
    for r in rows:
        print(f"{r['frames']:>6} {r['clip_fps']:>9.1f} {100 * r['clip_converged']:>9.0f}% {r['clip_error_px']:>6.2f} "
              f"{r['clip_pa_mm']:>6.1f} {r['frame_fps']:>10.1f} {100 * r['frame_converged']:>9.0f}% "
              f"{r['frame_error_px']:>6.2f} {r['frame_pa_mm']:>6.1f} {r['speedup']:>5.1f}x")
    result = dict(benchmark="fit_clip", threads=os.cpu_count(), machine=platform.machine(), jax=jax.__version__,
                  devices=[str(d) for d in jax.devices()], rows=rows)
    (out / "fit_clip.json").write_text(json.dumps(result, indent=2))
    print(f"wrote {out / 'fit_clip.json'}")


def fitting_errors(model, bodies, keypoints, lens):
    """Each valid frame's reprojection error of ``bodies`` through the pinhole ``lens``, pixels."""
    from jaxmocap.integrate import reprojection_errors

    errors = reprojection_errors(model, bodies.params, bodies.camera_scale, bodies.camera_trans, keypoints, *lens)
    return np.asarray(errors)[bodies.valid]


def frames_benchmark(args) -> None:
    """The per-frame fit against PyTorch (module docstring)."""

    import torch

    import smplx_jax
    from jaxmocap.integrate import fitting, reprojection_errors, synthetic
    from jaxmocap.integrate.camera import weak_perspective_from_points
    from jaxmocap.integrate.keypoints import keypoints_cm

    threads = os.cpu_count()
    path = smplx_jax.default_model_path()
    model = smplx_jax.load_model(path)
    km = fitting.openpose_keypoint_model(model)
    config = fitting.FitConfig()  # the objective PyTorch minimises, for as many steps as the pipeline takes
    cg_from_ik = fitting.FitConfig(**CG_FROM_IK)
    iterations = cg_from_ik.iterations
    settings = {"pipeline": cg_from_ik, "defaults": dataclasses.replace(config, iterations=fitting.ITERATIONS)}

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
    from jaxmocap.xla_options import configure_process

    configure_process()  # a command of the project: its process's settings before JAX starts
    main()
