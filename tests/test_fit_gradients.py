"""Gradients through the fit of one frame against central finite differences (float64): implicit differentiation
where the fit converged, the steps themselves where it was cut short."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

import smplx_jax
from fit64 import load64, synthetic64
from jaxmocap.integrate import fit_frame, fitting


def test_gradients_through_the_fit_match_finite_differences(x64, default_model_dir):
    """d(fitted right wrist, camera)/d(keypoints, confidences, start, camera) by implicit differentiation, against
    central differences of converged fits (float64, dense steps; priors 10x the defaults, with which this frame
    converges: see `test_unconverged_fits_are_flagged_and_differentiated_step_by_step` for the defaults); an unseen
    keypoint's position has no gradient."""
    model = load64(default_model_dir)
    kp, init = synthetic64(model, seed=11, noise_px=1.0, drop=0.15)
    camera = jnp.asarray([408.0, 481.0, 542.0])  # near the weak-perspective start (400, 478, 539)
    config = fitting.FitConfig(prior_global=0.05, prior_body=0.1, prior_hand=0.05, prior_betas=0.1)
    direction = jnp.asarray([0.3, -0.8, 0.5])

    @jax.jit
    def wrist_and_converged(kp, init, camera):
        result = fit_frame(model, kp, init, camera=camera, iterations=60, config=config)
        return smplx_jax.forward_joints(model, result.params)[21] @ direction + 1e-3 * result.camera_scale, \
            result.converged

    def wrist(*args):
        return wrist_and_converged(*args)[0]

    grads, converged = jax.jit(jax.grad(wrist_and_converged, argnums=(0, 1, 2), has_aux=True))(kp, init, camera)
    assert bool(converged)
    seen = np.flatnonzero(np.asarray(kp[:, 2]) > 0)
    unseen = np.flatnonzero(np.asarray(kp[:, 2]) == 0)
    assert len(unseen) and np.all(np.asarray(grads[0][unseen, :2]) == 0.0)  # an unseen keypoint's position: none
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


def test_unconverged_fits_are_flagged_and_differentiated_step_by_step(x64, default_model_dir):
    """At the defaults a fit cut short by its step cap says so, and ``adjoint=RecursiveCheckpointAdjoint()`` gives
    the derivative of the steps it took (central differences of the same capped fit)."""
    model = load64(default_model_dir)
    kp, init = synthetic64(model, seed=11, noise_px=1.0, drop=0.15)
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
