"""The stages of ``jaxmocap run``. Per chunk of frames: `observations` (the detector, each person by identity). Over the
whole sequence, for each person (split tracks joined: `merge_tracks`): `initial_bodies` (IK from the 3D landmarks,
placed in the camera; in windows placed by frame number, `whole_clip.with_start`) -> `whole_clip.fitted_track` (one
fit of the person's whole clip: the 2D keypoints, the 3D landmarks, anatomy, motion, one shape) -> `motion_arrays`
(what ``motion.npz`` holds); then the outputs (`outputs`). With FrankMocap's weights the regressors
(`regress.regressed_bodies`) give each frame's start instead (`placed_bodies`); with ``--integration copy-paste`` or
``eft`` their bodies are the motion as they are, with one shape (`median_shape`), unsmoothed as in FrankMocap,
which smooths only after its optimization."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

import smplx_jax
from jaxmocap.detect import Detector
from jaxmocap.detect.identities import IdentityTracker
from jaxmocap.integrate import body_from_blazepose, fitted_motion, hand_into_body
from jaxmocap.integrate.camera import default_focal_length, weak_perspective_from_points
from jaxmocap.integrate.fitting import openpose_keypoint_model, params_from_full_pose
from jaxmocap.integrate.keypoints import keypoints_cm
from jaxmocap.pipeline.observe import Observations, observe_people, repair_side_swaps
from jaxmocap.pipeline.tracks import Bodies

Lens = tuple[float, np.ndarray] | tuple[None, None]  # a pinhole camera's (focal_length, principal_point), or none


def observations(detector: Detector, tracker: IdentityTracker | None, frames: list[np.ndarray], fps: float | None,
                 given_keypoints: np.ndarray | None = None, previous: dict[int, np.ndarray] | None = None
                 ) -> tuple[dict[int, Observations], dict[int, np.ndarray]]:
    """Each person in the frames by identity (`observe_people`; the detector and ``tracker`` carry on from the
    frames before); in a video (``fps`` given) with left and right put back where the detector exchanged them
    (`repair_side_swaps`, from ``previous``: each identity's repaired keypoints (67, 3) in the frame before these);
    ``given_keypoints`` (N, 67, 3) replace the 2D keypoints of the one person tracked as the fit's targets. Also
    the repaired keypoints of the last frame by identity (where found there), for the frames after these."""
    people = observe_people(detector, tracker, frames)
    if fps is not None:
        people = {person_id: repair_side_swaps(obs, (previous or {}).get(person_id))
                  for person_id, obs in people.items()}
    last = {person_id: obs.keypoints[-1] for person_id, obs in people.items() if obs.found[-1]}
    if given_keypoints is not None:
        people = {person_id: dataclasses.replace(obs, keypoints=given_keypoints) for person_id, obs in people.items()}
    return people, last


def initial_poses(model: smplx_jax.BodyModel, obs: Observations) -> smplx_jax.SMPLXParams:
    """Each frame's pose from its 3D landmarks: IK of the body to BlazePose's world landmarks (starting from the
    torso's orientation), then of each hand to its landmarks with the body fixed (batched `SMPLXParams`, no
    translation; a hand seen in none of the frames, as with ``--mode body``, is left as the body IK starts it:
    flat)."""
    theta, betas, _, _ = body_from_blazepose(model, obs.body_world)
    for side, name in enumerate(smplx_jax.SIDES):
        if not np.any(obs.hands_conf[:, side] > 0):
            continue  # the IK would keep every frame as it is (too few targets)
        conf = np.repeat(obs.hands_conf[:, side:side + 1] > 0, 21, axis=1).astype(np.float32)
        theta, betas, _, _ = hand_into_body(model, name, obs.hands_world[:, side], theta, betas, conf=conf)
    return jax.block_until_ready(params_from_full_pose(jnp.asarray(theta), jnp.asarray(betas), model.num_expression))


@jax.jit
def placed(km, params, keypoints, focal_length, principal_point):
    """Each pose's translation in the camera frame: the depth and offset at which its keypoints' spread and
    centre match the 2D keypoints' (`weak_perspective_from_points`, as a pinhole camera sees the body's origin),
    and that camera."""
    def one(p, k):
        points = keypoints_cm(km, p.full_pose(), p.betas)
        scale, trans = weak_perspective_from_points(points[:2].T, k[:, :2], jnp.where(k[:, 2] > 0, k[:, 2], 0.0))
        return jnp.append((trans - principal_point) / scale, focal_length / scale), scale, trans

    transl, scale, trans = jax.vmap(one)(params, keypoints)
    return params.replace(transl=transl), scale, trans


def placed_bodies(model: smplx_jax.BodyModel, params: smplx_jax.SMPLXParams, keypoints_2d: np.ndarray, lens: Lens,
                  valid: np.ndarray) -> Bodies:
    """Each frame's pose (batched ``params``) placed in the pinhole camera ``lens`` (`placed`) on its 2D keypoints
    ``(T, 67, 3)``: a start for the clip fit."""
    params, scale, trans = placed(openpose_keypoint_model(model), params, np.asarray(keypoints_2d, np.float32),
                                  np.float32(lens[0]), np.asarray(lens[1], np.float32))
    return Bodies(jax.tree.map(np.asarray, params), np.asarray(scale), np.asarray(trans), np.asarray(valid))


def initial_bodies(model: smplx_jax.BodyModel, obs: Observations, lens: Lens) -> Bodies:
    """The clip fit's start for each frame: `initial_poses` placed in the pinhole camera ``lens``; valid where the
    person was found."""
    return placed_bodies(model, initial_poses(model, obs), obs.keypoints, lens, obs.found)


def lens_of(image_size: tuple[int, int], focal_length: float | None = None) -> Lens:
    """The pinhole camera of a run: ``focal_length`` pixels (default `default_focal_length`), centred on the image
    of ``image_size`` (width, height)."""
    return focal_length or default_focal_length(image_size), np.asarray(image_size, np.float32) / 2


def median_shape(bodies: Bodies) -> Bodies:
    """The bodies with one shape in every frame, the per-component median of the valid frames' ``betas`` (the
    regressors' estimates of one body: a person exports one bone length), their poses as they are."""
    if not bodies.valid.any():
        return bodies
    betas = np.broadcast_to(np.median(bodies.params.betas[bodies.valid], axis=0), bodies.params.betas.shape)
    return dataclasses.replace(bodies, params=bodies.params.replace(betas=np.array(betas, np.float32)))


def motion_arrays(model: smplx_jax.BodyModel, bodies: Bodies, keypoints_2d: np.ndarray, lens: Lens = (None, None)
                  ) -> dict[str, np.ndarray]:
    """``motion.npz``'s per-frame arrays (and the pinhole camera's keys when ``lens`` has one), with the
    reprojection errors of the parameters stored."""
    return fitted_motion(model, bodies.params, bodies.camera_scale, bodies.camera_trans, bodies.valid, keypoints_2d,
                         *lens)
