"""The optimistix fit of one frame: exact analytic Jacobians, the Levenberg-Marquardt model's gradient and Hessian
(dense and matrix-free), and jit = eager. All in float64 (gradients through the fit: `test_fit_gradients`)."""

import dataclasses
import functools

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest

import smplx_jax
from conftest import jit_fast_compile, programs_lowered
from fit64 import load64, synthetic64
from jaxmocap.integrate import fit_frame, fitting, keypoints, least_squares, levenberg_marquardt
from random_model import random_model_arrays
from smplx_jax import constants

OPENPOSE = np.asarray(constants.OPENPOSE67_FROM_SMPLX)


def _random_pose(seed):
    rng = np.random.default_rng(seed)
    return jnp.asarray(rng.normal(0, 0.5, (55, 3))), jnp.asarray(rng.normal(0, 1, 10)), rng


def test_keypoint_jacobian_is_exact(x64, model_dir):
    """The analytic JVP (and its second derivatives) equal autodiff of `forward_joints`, blended skinning and pose
    blend shapes included (the random model has both); the hand-written VJP is its transpose."""
    model = load64(model_dir)
    km = keypoints.keypoint_model(model, OPENPOSE)
    pose, betas, rng = _random_pose(0)
    tangents = (jnp.asarray(rng.normal(size=(55, 3))), jnp.asarray(rng.normal(size=10)))
    weights = jnp.asarray(rng.normal(size=(3, 67)))

    @jit_fast_compile
    def both(model, km, pose, betas):  # (ours, reference): values, JVPs, Hessian-vector products; transposes
        def reference(p, b):
            return smplx_jax.forward_joints(model, keypoints.params_of(p, b, model.num_expression))[OPENPOSE].T

        def hvp(f):
            gradient = jax.grad(lambda p, b: jnp.sum(weights * f(p, b) ** 2), argnums=(0, 1))
            return jax.jvp(gradient, (pose, betas), tangents)[1]

        functions = (functools.partial(keypoints.keypoints_cm, km), reference)
        lin = keypoints.linearize(km, pose, betas)
        transposes = [(jax.linear_transpose(lambda p, b, e=exact: keypoints.jvp(km, lin, p, b, exact=e), pose,
                                            betas)(weights), keypoints.vjp(km, lin, weights, exact=exact))
                      for exact in (True, False)]
        return ([f(pose, betas) for f in functions], [jax.jvp(f, (pose, betas), tangents)[1] for f in functions],
                [hvp(f) for f in functions], transposes)

    values, jvps, hvps, transposes = both(model, km, pose, betas)
    np.testing.assert_allclose(*values, atol=1e-12)
    np.testing.assert_allclose(*jvps, atol=1e-10)
    for a, b in zip(*map(jax.tree.leaves, hvps)):
        np.testing.assert_allclose(a, b, atol=1e-9)
    for transposed, vjp in transposes:
        for a, b in zip(transposed, vjp):
            np.testing.assert_allclose(a, b, atol=1e-10)


def test_keypoint_constants_are_built_once_and_never_traced(model_dir):
    """A concrete model's constants are built once, concrete even when first asked for inside `jax.jit` (then used
    outside it); a traced model's belong to its trace."""
    model = smplx_jax.load_model(model_dir / "smplx" / "SMPLX_NEUTRAL.npz")
    index = OPENPOSE[:5] + 1
    inside = jax.jit(lambda: keypoints.keypoint_model(model, index).reach.sum())()
    km = keypoints.keypoint_model(model, index)
    assert not any(isinstance(leaf, jax.core.Tracer) for leaf in jax.tree.leaves(km))
    assert keypoints.keypoint_model(model, index) is km
    np.testing.assert_allclose(inside, km.reach.sum(), rtol=1e-6)
    traced = jax.jit(lambda m: keypoints.keypoint_model(m, index).reach.sum())(model)
    np.testing.assert_allclose(traced, inside, rtol=1e-6)


def test_a_model_file_its_hands_and_keypoint_constants_lower_few_programs(tmp_path):
    """Loading a model file and cutting a hand model from it lower no program (NumPy converts and cuts the arrays),
    and a concrete model's keypoint constants lower one program, not one for each of their ~30 operations (in a new
    process each is read back from the compile cache: 0.75 s for a run's three keypoint sets), and hold what those
    operations give one by one."""
    (tmp_path / "smplx").mkdir()
    np.savez(tmp_path / "smplx" / "SMPLX_NEUTRAL.npz", **random_model_arrays(seed=5))
    index = np.array([0, 4, 7, 60])  # a set no other test builds: its program is new to this process
    # another set of as many: the few small programs that prepare any set's arguments, lowered before the block
    keypoints.keypoint_model(smplx_jax.load_model(tmp_path / "smplx" / "SMPLX_NEUTRAL.npz"), np.array([1, 5, 8, 61]))
    with programs_lowered() as lowered:
        model = smplx_jax.load_model(tmp_path / "smplx" / "SMPLX_NEUTRAL.npz")
        smplx_jax.hand_model(model, "left")
        loading = len(lowered)
        km = keypoints.keypoint_model(model, index)
    assert (loading, len(lowered) - loading) == (0, 1)
    with jax.ensure_compile_time_eval():
        one_by_one = keypoints._keypoint_model(model, index)
    assert jax.tree.structure(km) == jax.tree.structure(one_by_one) and km.pose_correctives
    for ours, theirs in zip(jax.tree.leaves(km), jax.tree.leaves(one_by_one)):
        np.testing.assert_allclose(ours, theirs, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("focal", [None, 1500.0])
def test_the_solvers_model_has_the_costs_gradient(x64, default_model_dir, focal):
    """The local model's gradient is the gradient of the cost optimistix minimises in the steps' coordinates (the
    rotations' local increments, `levenberg_marquardt.retract`), with joints held fixed, under
    weak perspective and a pinhole camera; its Hessian is symmetric positive semi-definite, and the dense one
    (``"cholesky"``, over a subset of joints) is the matrix-free one (``"cg"``) restricted to those joints."""
    model = load64(default_model_dir)
    km = fitting.openpose_keypoint_model(model)
    kp, init = synthetic64(model, seed=3)
    pose, betas = init.full_pose(), init.betas
    config = fitting.FitConfig()
    free = jnp.ones(55).at[3:9].set(0.0)
    problem = least_squares.Problem(km, kp[:, :2], kp[:, 2], pose, betas,
                                    jnp.asarray(fitting.prior_weights(config), jnp.float64),
                                    jnp.asarray(400.0, jnp.float64), free, jnp.asarray(1.0, jnp.float64),
                                    jnp.asarray(0.0 if focal is None else 1 / focal), jnp.asarray([470.0, 500.0]))
    rng = np.random.default_rng(1)
    y = least_squares.Unknowns(pose + 0.3 * jnp.asarray(rng.normal(size=(55, 3))), betas + 0.1,
                               jnp.asarray([np.log(390.0), 480.0, 510.0]))
    y = y._replace(pose_rotvecs=y.pose_rotvecs.at[19, 1].set(0.2))  # a bending limit active
    flat, unflat = jax.flatten_util.ravel_pytree(y)
    joints = (0, 2, 9, 12, 16, 18, 21, 30, 44)  # 3..8 are held fixed by the problem: their rows are the identity
    chol_config = dataclasses.replace(config, joints=joints + (3, 4))

    @jit_fast_compile
    def models(y, problem):  # the matrix-free model's gradient and its Hessian as a matrix, the dense model's
        cg = levenberg_marquardt.local_model(y, problem, dataclasses.replace(config, linear_solver="cg"))
        columns = jax.vmap(lambda e: jax.flatten_util.ravel_pytree(cg.hessian(unflat(e)))[0])(jnp.eye(flat.size))
        chol = levenberg_marquardt.local_model(y, problem, chol_config)
        return cg.gradient, columns.T, chol.gradient, chol.dense

    @jit_fast_compile
    def cost_gradient(y, problem):  # in the local increments of the rotations the solver steps by
        zero = jax.tree.map(jnp.zeros_like, y)
        def cost(step):
            parts = least_squares.residuals(levenberg_marquardt.retract(y, step), problem, config)
            return 0.5 * sum(jnp.sum(part * part) for part in parts)

        return jax.grad(cost)(zero)

    cg_gradient, dense, chol_gradient, chol_dense = models(y, problem)
    for a, b in zip(cg_gradient, cost_gradient(y, problem)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9 * float(jnp.abs(b).max()))
    np.testing.assert_allclose(dense, dense.T, rtol=0, atol=1e-9 * float(jnp.abs(dense).max()))
    assert float(jnp.linalg.eigvalsh(dense)[0]) > -1e-9 * float(jnp.abs(dense).max())
    index = np.concatenate([np.stack([3 * j, 3 * j + 1, 3 * j + 2]) for j in joints + (3, 4)] + [165 + np.arange(13)])
    expected = np.asarray(dense)[np.ix_(index, index)]
    expected[np.arange(27, 33), np.arange(27, 33)] = 1.0
    np.testing.assert_allclose(chol_dense, expected, rtol=1e-9, atol=1e-9 * float(jnp.abs(dense).max()))
    moved = np.zeros((55, 1))
    moved[list(joints)] = 1.0  # the others keep their start: no gradient
    expected = cg_gradient._replace(pose_rotvecs=cg_gradient.pose_rotvecs * moved)
    for a, b in zip(chol_gradient, expected):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12 * float(jnp.abs(b).max()))


def test_jit_equals_eager(x64, default_model_dir):
    """The jitted fit equals the eager one."""
    model = load64(default_model_dir)
    kp, init = synthetic64(model, seed=4)
    kp = kp.at[5].set(0.0)
    one = functools.partial(fit_frame, model, iterations=5)
    eager, jitted = one(kp, init), jit_fast_compile(one)(kp, init)
    for a, b in zip(jax.tree.leaves(eager), jax.tree.leaves(jitted)):
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-9)
    assert int(eager.status) == fitting.OK and not bool(eager.converged) and int(eager.steps) == 5  # cut short
    assert float(eager.reprojection_error_px) < 0.5 * float(eager.initial_reprojection_error_px)


def test_a_solve_paused_and_resumed_takes_the_steps_of_one_solve(x64, default_model_dir):
    """`levenberg_marquardt.solve` paused at a step count (``until``) and resumed from its state (``resume``), as
    `fit`'s rounds run it, lands where one solve does, step for step."""
    model = load64(default_model_dir)
    km = fitting.openpose_keypoint_model(model)
    kp, init = synthetic64(model, seed=5)
    config = fitting.FitConfig(iterations=30)
    problem, start, _ = fitting._problem(km, kp, init.full_pose(), init.betas, None,
                                         fitting.lens_arrays(None, None, jnp.float64), config, None, None)
    piece = jit_fast_compile(lambda y, state, until: (lambda s: (s.value, s.state))(
        levenberg_marquardt.solve(problem, y, config, resume=state, until=until)))
    first = levenberg_marquardt.initial_state(problem, start, config)
    whole, whole_state = piece(start, first, jnp.asarray(30))
    y, state = start, first
    for until in (7, 19, 30):
        y, state = piece(y, state, jnp.asarray(until))
        assert int(state.steps) == min(until, int(whole_state.steps))
    assert int(whole_state.steps) > 19
    for a, b in zip(jax.tree.leaves((whole, whole_state)), jax.tree.leaves((y, state))):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)


def test_a_solve_stalled_at_its_damping_cap_restarts_once_then_stops_unconverged(x64, default_model_dir):
    """Refused steps that raise the damping to its cap start the solve again at damping 1 without the secant ``S``
    (the refusals that shrank ``S`` ran the damping past every step that lowers the cost); the second time it stops
    (in float32 the later steps would all be refused in place, holding up the batch: `levenberg_marquardt.stalled`),
    reported not converged."""
    model = load64(default_model_dir)
    km = fitting.openpose_keypoint_model(model)
    kp, init = synthetic64(model, seed=3)
    config = fitting.FitConfig()
    problem, start, _ = fitting._problem(km, kp, init.full_pose(), init.betas, None,
                                         fitting.lens_arrays(None, None, jnp.float64), config, None, None)
    solver = levenberg_marquardt.LevenbergMarquardt(config, levenberg_marquardt.default_tolerance(jnp.float64))
    state = levenberg_marquardt.initial_state(problem, start, config)

    def fn(y, problem):  # the residuals as `optimistix.least_squares` gives them to its solver
        return least_squares.residuals(y, problem, config), None

    assert not bool(solver.terminate(fn, start, problem, {}, state, frozenset())[0])
    step = jit_fast_compile(lambda y, state: solver.step(fn, y, problem, {}, state, frozenset())[:2])
    # a state no step can improve on (its cost 0), one refusal short of the cap, with a secant
    near_cap = eqx.tree_at(lambda s: (s.cost, s.damping, s.secant), state,
                           (jnp.zeros((), jnp.float64), jnp.asarray(levenberg_marquardt.MAX_DAMPING / 1.5),
                            jnp.eye(state.secant.shape[0])))
    y, restarted = step(start, near_cap)
    assert float(restarted.damping) == 1.0 and float(restarted.growth) == 2.0 and bool(restarted.restarted)
    assert not np.asarray(restarted.secant).any() and not bool(levenberg_marquardt.stalled(restarted))
    assert not bool(solver.terminate(fn, y, problem, {}, restarted, frozenset())[0])
    _, stalled = step(y, eqx.tree_at(lambda s: (s.damping, s.growth), restarted,
                                     (near_cap.damping, near_cap.growth)))
    assert float(stalled.damping) == levenberg_marquardt.MAX_DAMPING and bool(levenberg_marquardt.stalled(stalled))
    stop, result = solver.terminate(fn, y, problem, {}, stalled, frozenset())
    assert bool(stop) and result == optx.RESULTS.nonlinear_max_steps_reached
