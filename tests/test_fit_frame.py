"""The optimistix fit of one frame: exact analytic Jacobians, the Levenberg-Marquardt model's gradient and Hessian
(dense and matrix-free), gradients through the fit (implicit differentiation where it converged, the steps
themselves otherwise) against finite differences, and jit = eager. All in float64."""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import smplx_jax
from jaxmocap.integrate import fit_frame, fitting, keypoints, least_squares, levenberg_marquardt, synthetic
from smplx_jax import constants

OPENPOSE = np.asarray(constants.OPENPOSE67_FROM_SMPLX)


@pytest.fixture(scope="module")
def x64():
    with jax.enable_x64(True):
        yield


def _load64(model_dir):
    return smplx_jax.load_model(model_dir / "smplx" / "SMPLX_NEUTRAL.npz", dtype=jnp.float64)


def _synthetic64(model, **kwargs):
    """A one-frame synthetic problem in float64: keypoints (67, 3) and the start."""
    data = synthetic.make_problem(model, 1, **kwargs)
    return jnp.asarray(data.keypoints[0], jnp.float64), jax.tree.map(lambda a: jnp.asarray(a[0], jnp.float64),
                                                                      data.init)


def _random_pose(seed):
    rng = np.random.default_rng(seed)
    return jnp.asarray(rng.normal(0, 0.5, (55, 3))), jnp.asarray(rng.normal(0, 1, 10)), rng


def test_keypoint_jacobian_is_exact(x64, model_dir):
    """The analytic JVP (and its second derivatives) equal autodiff of `forward_joints`, blended skinning and pose
    blend shapes included (the random model has both); the hand-written VJP is its transpose."""
    model = _load64(model_dir)
    km = keypoints.keypoint_model(model, OPENPOSE)
    pose, betas, rng = _random_pose(0)
    ours = functools.partial(keypoints.keypoints_cm, km)

    def reference(p, b):
        return smplx_jax.forward_joints(model, keypoints.params_of(p, b, model.num_expression))[OPENPOSE].T

    np.testing.assert_allclose(ours(pose, betas), reference(pose, betas), atol=1e-12)
    tangents = (jnp.asarray(rng.normal(size=(55, 3))), jnp.asarray(rng.normal(size=10)))
    np.testing.assert_allclose(jax.jvp(ours, (pose, betas), tangents)[1],
                               jax.jvp(reference, (pose, betas), tangents)[1], atol=1e-10)
    weights = jnp.asarray(rng.normal(size=(3, 67)))
    second = [jax.jvp(jax.grad(lambda p, b: jnp.sum(weights * f(p, b) ** 2), argnums=(0, 1)), (pose, betas),
                      tangents)[1] for f in (ours, reference)]  # Hessian-vector products
    for a, b in zip(*map(jax.tree.leaves, second)):
        np.testing.assert_allclose(a, b, atol=1e-9)
    lin = keypoints.linearize(km, pose, betas)
    for exact in (True, False):
        transposed = jax.linear_transpose(lambda p, b: keypoints.jvp(km, lin, p, b, exact=exact), pose, betas)
        for a, b in zip(transposed(weights), keypoints.vjp(km, lin, weights, exact=exact)):
            np.testing.assert_allclose(a, b, atol=1e-10)


@pytest.mark.parametrize("focal", [None, 1500.0])
def test_the_solvers_model_has_the_costs_gradient(x64, default_model_dir, focal):
    """The local model's gradient is the gradient of the cost optimistix minimises, with joints held fixed, under
    weak perspective and a pinhole camera; its Hessian is symmetric positive semi-definite, and the dense one
    (``"cholesky"``, over a subset of joints) is the matrix-free one (``"cg"``) restricted to those joints."""
    model = _load64(default_model_dir)
    km = fitting.openpose_keypoint_model(model)
    kp, init = _synthetic64(model, seed=3)
    pose, betas = init.full_pose(), init.betas
    config = fitting.FitConfig()
    free = jnp.ones(55).at[3:9].set(0.0)
    problem = least_squares.Problem(km, kp[:, :2], kp[:, 2], pose, betas, jnp.asarray(fitting.prior_weights(config)),
                                    jnp.asarray(400.0), free, jnp.asarray(1.0),
                                    jnp.asarray(0.0 if focal is None else 1 / focal), jnp.asarray([470.0, 500.0]))
    rng = np.random.default_rng(1)
    y = least_squares.Unknowns(pose + 0.3 * jnp.asarray(rng.normal(size=(55, 3))), betas + 0.1,
                               jnp.asarray([np.log(390.0), 480.0, 510.0]))
    y = y._replace(pose_rotvecs=y.pose_rotvecs.at[19, 1].set(0.2))  # a bending limit active
    cg = levenberg_marquardt.local_model(y, problem, dataclasses.replace(config, linear_solver="cg"))
    for a, b in zip(cg.gradient, jax.grad(levenberg_marquardt.cost_of)(y, problem, config)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * float(jnp.abs(b).max()))
    flat, unflat = jax.flatten_util.ravel_pytree(y)
    dense = jnp.stack([jax.flatten_util.ravel_pytree(cg.hessian(unflat(e)))[0] for e in jnp.eye(flat.size)], 1)
    np.testing.assert_allclose(dense, dense.T, rtol=0, atol=1e-9 * float(jnp.abs(dense).max()))
    assert float(jnp.linalg.eigvalsh(dense)[0]) > -1e-9 * float(jnp.abs(dense).max())
    joints = (0, 2, 9, 12, 16, 18, 21, 30, 44)  # 3..8 are held fixed by the problem: their rows are the identity
    chol_config = dataclasses.replace(config, joints=joints + (3, 4))
    chol = levenberg_marquardt.local_model(y, problem, chol_config)
    index = np.concatenate([np.stack([3 * j, 3 * j + 1, 3 * j + 2]) for j in joints + (3, 4)] + [165 + np.arange(13)])
    expected = np.asarray(dense)[np.ix_(index, index)]
    expected[np.arange(27, 33), np.arange(27, 33)] = 1.0
    np.testing.assert_allclose(chol.dense, expected, rtol=1e-9, atol=1e-9 * float(jnp.abs(dense).max()))
    moved = np.zeros((55, 1))
    moved[list(joints)] = 1.0  # the others keep their start: no gradient
    expected = cg.gradient._replace(pose_rotvecs=cg.gradient.pose_rotvecs * moved)
    for a, b in zip(chol.gradient, expected):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * float(jnp.abs(b).max()))


def test_gradients_through_the_fit_match_finite_differences(x64, default_model_dir):
    """d(fitted right wrist, camera)/d(keypoints, confidences, start, camera) by implicit differentiation, against
    central differences of converged fits (float64, dense steps; priors 10x the defaults, with which this frame
    converges: see `test_unconverged_fits_are_flagged_and_differentiated_step_by_step` for the defaults)."""
    model = _load64(default_model_dir)
    kp, init = _synthetic64(model, seed=11, noise_px=1.0, drop=0.15)
    camera = jnp.asarray([408.0, 481.0, 542.0])  # near the weak-perspective start (400, 478, 539)
    config = fitting.FitConfig(prior_global=0.05, prior_body=0.1, prior_hand=0.05, prior_betas=0.1)
    direction = jnp.asarray([0.3, -0.8, 0.5])
    assert bool(fit_frame(model, kp, init, camera=camera, iterations=60, config=config).converged)

    @jax.jit
    def wrist(kp, init, camera):
        result = fit_frame(model, kp, init, camera=camera, iterations=60, config=config)
        return smplx_jax.forward_joints(model, result.params)[21] @ direction + 1e-3 * result.camera_scale

    grads = jax.jit(jax.grad(wrist, argnums=(0, 1, 2)))(kp, init, camera)
    seen = np.flatnonzero(np.asarray(kp[:, 2]) > 0)
    probes = [(0, (int(seen[3]), 0), 0.1), (0, (int(seen[3]), 1), 0.1), (0, (int(seen[20]), 0), 0.1),
              (0, (int(seen[9]), 2), 0.01), (1, ("body_pose", 17, 1), 0.01), (1, ("global_orient", 0), 0.01),
              (2, (0,), 1.0)]
    for arg, where, h in probes:
        def shifted(delta, arg=arg, where=where):
            args = [kp, init, camera]
            if arg == 1:
                field, *index = where
                args[1] = init.replace(**{field: getattr(init, field).at[tuple(index)].add(delta)})
            else:
                args[arg] = args[arg].at[where].add(delta)
            return wrist(*args)

        numeric = float((shifted(h) - shifted(-h)) / (2 * h))
        analytic = float(getattr(grads[1], where[0])[where[1:]] if arg == 1 else grads[arg][where])
        assert abs(analytic - numeric) <= 1e-3 * abs(numeric), (arg, where, analytic, numeric)
        assert abs(numeric) > 1e-7, (arg, where)  # a probe that says something
    # the start camera's translation is only the solver's start: no effect on a converged fit
    assert float(jnp.abs(grads[2][1:]).max()) == 0.0


def test_jit_equals_eager_and_unseen_keypoints_have_zero_gradient(x64, default_model_dir):
    model = _load64(default_model_dir)
    kp, init = _synthetic64(model, seed=4)
    kp = kp.at[5].set(0.0)
    one = functools.partial(fit_frame, model, iterations=5)
    eager, jitted = one(kp, init), jax.jit(one)(kp, init)
    for a, b in zip(jax.tree.leaves(eager), jax.tree.leaves(jitted)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
    assert int(eager.status) == fitting.OK and not bool(eager.converged)  # 5 steps: cut short
    assert float(eager.reprojection_error_px) < 0.5 * float(eager.initial_reprojection_error_px)
    grad = jax.grad(lambda kp: jnp.sum(one(kp, init).params.body_pose))(kp)
    assert np.all(np.isfinite(grad)) and np.all(np.asarray(grad[5, :2]) == 0.0)  # its confidence moves the camera


def test_unconverged_fits_are_flagged_and_differentiated_step_by_step(x64, default_model_dir):
    """At the defaults a fit cut short by its step cap says so, and ``adjoint=RecursiveCheckpointAdjoint()`` gives
    the derivative of the steps it took (central differences of the same capped fit)."""
    model = _load64(default_model_dir)
    kp, init = _synthetic64(model, seed=11, noise_px=1.0, drop=0.15)
    direction = jnp.asarray([0.3, -0.8, 0.5])

    @functools.partial(jax.jit, static_argnames="adjoint")
    def wrist(kp, adjoint=None):
        result = fit_frame(model, kp, init, iterations=4, adjoint=adjoint)
        return smplx_jax.forward_joints(model, result.params)[21] @ direction, result.converged

    assert not bool(wrist(kp)[1])
    grad = jax.grad(lambda kp: wrist(kp, optx.RecursiveCheckpointAdjoint())[0])(kp)
    seen = np.flatnonzero(np.asarray(kp[:, 2]) > 0)
    for where in ((int(seen[3]), 0), (int(seen[20]), 1), (int(seen[9]), 2)):
        h = 1e-3 if where[1] < 2 else 1e-5
        numeric = float((wrist(kp.at[where].add(h))[0] - wrist(kp.at[where].add(-h))[0]) / (2 * h))
        assert abs(float(grad[where]) - numeric) <= 1e-3 * abs(numeric) and abs(numeric) > 1e-7, (where, numeric)


def test_readmes_fitting_in_the_loop_lowers_its_loss(capsys):
    """README's example, run as written (float32): the loss after its ten Adam steps is at least 5% lower."""
    import re
    from pathlib import Path

    readme = (Path(__file__).parent.parent / "README.md").read_text()
    block = next(b for b in re.findall(r"```python\n(.*?)```", readme, re.S) if "Fitting in the loop" in b)
    with jax.enable_x64(False):  # as a user runs it (this module's other tests run in float64)
        exec(compile(block, "README.md", "exec"), {})
    losses = [float(v) for v in re.findall(r"loss ([0-9.e-]+)", capsys.readouterr().out)]
    assert len(losses) == 10 and losses[-1] <= 0.95 * losses[0], losses
