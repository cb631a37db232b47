"""Per-frame fits (smoothed or not) -> the arrays of ``motion.npz``, with the reprojection errors of what is stored
(so that the file's errors are those of its own parameters)."""

import jax
import jax.numpy as jnp
import numpy as np

import smplx_jax
from jaxmocap.buckets import map_in_buckets
from jaxmocap.integrate import fitting
from jaxmocap.integrate.camera import project
from smplx_jax import constants

_OPENPOSE = np.asarray(constants.OPENPOSE67_FROM_SMPLX)


@jax.jit
def _errors(model, params, scale, trans, keypoints, focal_length, principal_point):
    joints = jax.vmap(smplx_jax.forward_joints, in_axes=(None, 0))(model, params)[:, _OPENPOSE]
    pix = project(joints, scale, trans, focal_length, principal_point)
    seen = keypoints[..., 2] > 0
    dist = jnp.where(seen, jnp.linalg.norm(pix - keypoints[..., :2], axis=-1), 0.0)
    return dist.sum(1) / jnp.maximum(seen.sum(1), 1)


_JOINTS = jax.jit(jax.vmap(smplx_jax.forward_joints, in_axes=(None, 0)))


def body_joints(model: smplx_jax.BodyModel, params: smplx_jax.SMPLXParams) -> np.ndarray:
    """``(T, 127, 3)`` the joints of each frame's body in the frame its ``transl`` is in (the camera's, or the
    world's of motion.npz's world keys). One compiled program per bucket (`fitting.BUCKETS`)."""
    params = jax.tree.map(lambda a: np.asarray(a, np.float32), params)
    return map_in_buckets(lambda chunk, _: np.asarray(_JOINTS(model, chunk)), params, fitting.BUCKETS)


def reprojection_errors(model, params, scale, trans, keypoints, focal_length=None, principal_point=None) -> np.ndarray:
    """Mean pixel distance per frame over keypoints with confidence > 0 (0 where none); the pinhole camera's
    pixels when ``focal_length`` is given, else the weak-perspective camera's. One compiled program per bucket
    (`fitting.BUCKETS`), whatever the number of frames."""
    lens = (None, None) if focal_length is None else (np.float32(focal_length), np.asarray(principal_point, np.float32))
    frames = jax.tree.map(lambda a: np.asarray(a, np.float32), (params, scale, trans, keypoints))
    return map_in_buckets(lambda chunk, _: np.asarray(_errors(model, *chunk, *lens)), frames, fitting.BUCKETS)


def fitted_motion(model, params: smplx_jax.SMPLXParams, camera_scale, camera_trans, valid, keypoints,
                  focal_length=None, principal_point=None) -> dict[str, np.ndarray]:
    """``motion.npz`` arrays (all but ``fps``, ``image_size``, ``model_sha256``) of batched fits, with the pinhole
    camera's ``focal_length`` and ``principal_point`` when given; invalid frames keep their parameters and get
    error 0."""
    valid = np.asarray(valid, bool)
    scale, trans = np.asarray(camera_scale, np.float32), np.asarray(camera_trans, np.float32)
    keypoints = np.asarray(keypoints, np.float32)
    errors = reprojection_errors(model, params, scale, trans, keypoints, focal_length, principal_point)
    pinhole = {} if focal_length is None else {"focal_length": np.asarray(focal_length, np.float32),
                                               "principal_point": np.asarray(principal_point, np.float32)}
    arrays = {k: np.asarray(getattr(params, k), np.float32) for k in (
        "global_orient", "body_pose", "left_hand_pose", "right_hand_pose", "jaw_pose", "betas", "transl")}
    return arrays | {"camera_scale": np.asarray(scale, np.float32), "camera_trans": np.asarray(trans, np.float32),
                     "valid": valid, "keypoints_2d": keypoints,
                     "reprojection_error_px": np.where(valid, errors, 0.0).astype(np.float32)} | pinhole
