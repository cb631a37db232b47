"""Gradients through the fit of one frame against central finite differences (float64): implicit differentiation
where the fit converged, the steps themselves where it was cut short."""

import functools
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

import smplx_jax
from conftest import jit_fast_compile
from fit64 import load64, synthetic64
from jaxmocap.integrate import fit_frame
from jaxmocap.integrate.camera import default_focal_length
from jaxmocap.integrate.keypoints import params_of

DIRECTION = np.array([0.3, -0.8, 0.5])  # the wrist position's component the tests differentiate


def _assert_matches_central_differences(value_and_grads, args, probes):
    """``value_and_grads(*args)``: ``((value, converged), gradients)``, one compiled program for both. Each probe
    ``(argument index, where, step)`` (``where`` into an array, or ``(field, *index)`` into the start's
    `SMPLXParams`): the analytic gradient within 1e-2 relative of central differences of the value, and the
    difference not negligible (a probe that says something)."""
    (_, converged), grads = value_and_grads(*args)
    assert bool(converged)
    for arg, where, h in probes:
        def shifted(delta, arg=arg, where=where):
            moved = list(args)
            if where and isinstance(where[0], str):
                field, *index = where
                moved[arg] = args[arg].replace(**{field: getattr(args[arg], field).at[tuple(index)].add(delta)})
            else:
                moved[arg] = args[arg].at[where].add(delta)
            return value_and_grads(*moved)[0][0]

        numeric = float((shifted(h) - shifted(-h)) / (2 * h))
        analytic = float(getattr(grads[arg], where[0])[tuple(where[1:])] if where and isinstance(where[0], str)
                         else grads[arg][where])
        print(arg, where, f"relative difference {abs(analytic - numeric) / abs(numeric):.1e}")
        assert abs(analytic - numeric) <= 1e-2 * abs(numeric), (arg, where, analytic, numeric)
        assert abs(numeric) > 1e-7, (arg, where)
    return grads


def test_gradients_through_the_fit_match_finite_differences(x64, default_model_dir):
    """At the defaults (float64, weak perspective): d(fitted right wrist, camera)/d(keypoints, confidences, start,
    camera) by implicit differentiation, against central differences of the converged fits (on the frame of
    seed 11 a 0.1 px nudge moves some fits into another minimum, so differences there say nothing); an unseen
    keypoint's position has no gradient."""
    model = load64(default_model_dir)
    kp, init = synthetic64(model, seed=3, noise_px=1.0, drop=0.15)
    camera = jnp.asarray([408.0, 481.0, 542.0])  # the solve's start camera (scale, tx, ty)

    @jit_fast_compile
    @functools.partial(jax.value_and_grad, argnums=(0, 1, 2), has_aux=True)
    def wrist_and_converged(kp, init, camera):
        result = fit_frame(model, kp, init, camera=camera)
        return smplx_jax.forward_joints(model, result.params)[21] @ DIRECTION + 1e-3 * result.camera_scale, \
            result.converged

    seen = np.flatnonzero(np.asarray(kp[:, 2]) > 0)
    unseen = np.flatnonzero(np.asarray(kp[:, 2]) == 0)
    probes = [(0, (int(seen[3]), 0), 0.1), (0, (int(seen[3]), 1), 0.1), (0, (int(seen[20]), 0), 0.1),
              (0, (int(seen[3]), 2), 0.05), (1, ("body_pose", 17, 1), 0.01), (1, ("global_orient", 0), 0.05),
              (2, (0,), 1.0)]
    grads = _assert_matches_central_differences(wrist_and_converged, (kp, init, camera), probes)
    assert len(unseen) and np.all(np.asarray(grads[0][unseen, :2]) == 0.0)  # an unseen keypoint's position: none
    # the start camera's translation is only the solver's start: no effect on a converged fit
    assert float(jnp.abs(grads[2][1:]).max()) == 0.0


def test_gradients_through_a_real_frames_fit_match_finite_differences(x64, default_model_dir):
    """The same at the defaults on a real frame (frame 0 of the shipped cam01 clip, as the run observed it: our
    detector's keypoints, the run's start, its pinhole camera): d(fitted right wrist, depth)/d(keypoints,
    confidences, start, focal length)."""
    model = load64(default_model_dir)
    data = np.load(Path(__file__).parent / "data" / "pose2sim_cam01_f000_observed.npz")
    kp = jnp.asarray(data["keypoints"], jnp.float64)
    init = params_of(jnp.asarray(data["pose_rotvecs"], jnp.float64), jnp.asarray(data["betas"], jnp.float64),
                     model.num_expression)
    size = np.asarray(data["image_size"], np.float64)
    focal = jnp.asarray(default_focal_length(tuple(size)), jnp.float64)

    @jit_fast_compile
    @functools.partial(jax.value_and_grad, argnums=(0, 1, 2), has_aux=True)
    def wrist_and_converged(kp, init, focal):
        result = fit_frame(model, kp, init, focal_length=focal, principal_point=jnp.asarray(size / 2))
        return smplx_jax.forward_joints(model, result.params)[21] @ DIRECTION + 1e-3 * result.params.transl[2], \
            result.converged

    seen = np.flatnonzero(np.asarray(kp[:, 2]) > 0)
    # keypoints moved by 0.3 px: the fit ends within its tolerance of the optimum, which moves differences of 0.1 px
    # by up to 2% here (0.3, 0.1, 0.03 px: 0.000552, 0.000540, 0.000555 against the implicit 0.000552)
    probes = [(0, (int(seen[3]), 0), 0.3), (0, (int(seen[3]), 1), 0.3), (0, (int(seen[20]), 0), 0.3),
              (0, (int(seen[9]), 2), 0.01), (1, ("body_pose", 17, 1), 0.01), (1, ("global_orient", 0), 0.01),
              (2, (), 10.0)]
    _assert_matches_central_differences(wrist_and_converged, (kp, init, focal), probes)


def test_unconverged_fits_are_flagged_and_differentiated_step_by_step(x64, default_model_dir):
    """At the defaults a fit cut short by its step cap says so, and ``adjoint=RecursiveCheckpointAdjoint()`` gives
    the derivative of the steps it took (central differences of the same capped fit)."""
    model = load64(default_model_dir)
    kp, init = synthetic64(model, seed=11, noise_px=1.0, drop=0.15)

    @jit_fast_compile
    @functools.partial(jax.value_and_grad, has_aux=True)  # one program for the values and the gradient
    def wrist(kp):
        result = fit_frame(model, kp, init, iterations=4, adjoint=optx.RecursiveCheckpointAdjoint())
        return smplx_jax.forward_joints(model, result.params)[21] @ DIRECTION, result.converged

    (_, converged), grad = wrist(kp)
    assert not bool(converged)
    seen = np.flatnonzero(np.asarray(kp[:, 2]) > 0)
    for where in ((int(seen[3]), 0), (int(seen[20]), 1), (int(seen[9]), 2)):
        h = 1e-3 if where[1] < 2 else 1e-5
        numeric = float((wrist(kp.at[where].add(h))[0][0] - wrist(kp.at[where].add(-h))[0][0]) / (2 * h))
        assert abs(float(grad[where]) - numeric) <= 1e-3 * abs(numeric) and abs(numeric) > 1e-7, (where, numeric)
