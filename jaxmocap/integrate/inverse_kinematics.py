"""Inverse kinematics from 3D landmarks: the embedded default's initial whole-body pose, no trained network.

Targets are metric 3D points in image-aligned axes (x right, y down, z away from the camera): mediapipe's
BlazePose world landmarks (metres about the hips) and each hand's 21 world landmarks, or any 3D joints. The
least-squares solver of the 2D fit (`levenberg_marquardt`'s steps with D = 3) fits joint rotations together with a
free scale and offset per target set, so the residuals are scale- and offset-free: BlazePose's hip centre is not
SMPL-X's pelvis and its skeleton is not ours; what is fitted is the shape of the point set, i.e. bone directions.
Hands are fitted after the body with the body fixed: the wrist's local rotation and the 15 finger joints of that
side (the hand's own scale and offset free), so the hand's global orientation is pasted under the body's forward
kinematics as copy-and-paste does.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from scipy.spatial.transform import Rotation

from jaxmocap.buckets import map_in_buckets
from jaxmocap.compile_cache import disk_jit
from jaxmocap.integrate import least_squares, levenberg_marquardt
from jaxmocap.integrate.fitting import BUCKETS, default_pose
from jaxmocap.integrate.keypoints import keypoint_model, keypoints_cm, params_of
from smplx_jax import BodyModel, constants, forward_joints

forward_joints_jit = jax.jit(forward_joints)

# BlazePose landmark -> SMPL-X output joint (127-joint index); eyes/ears/heels/toes are vertex joints.
BLAZEPOSE_TO_SMPLX = {0: 55, 2: 57, 5: 56, 7: 59, 8: 58, 11: 16, 12: 17, 13: 18, 14: 19, 15: 20, 16: 21, 23: 1,
                      24: 2, 25: 4, 26: 5, 27: 7, 28: 8, 29: 62, 30: 65, 31: 60, 32: 63}
# Landmarks that sit elsewhere than their SMPL-X counterparts (hip joints inside the pelvis, face points on the
# surface) get less weight.
BLAZEPOSE_WEIGHT = {0: 0.3, 2: 0.3, 5: 0.3, 7: 0.3, 8: 0.3, 23: 0.5, 24: 0.5}

_BLAZEPOSE_IDS = list(BLAZEPOSE_TO_SMPLX)
BLAZEPOSE_JOINTS = [BLAZEPOSE_TO_SMPLX[i] for i in _BLAZEPOSE_IDS]  # the SMPL-X joints `blazepose_targets` are of
_BLAZEPOSE_WEIGHTS = np.array([BLAZEPOSE_WEIGHT.get(i, 1.0) for i in _BLAZEPOSE_IDS], np.float32)


def blazepose_targets(world):
    """The IK targets of BlazePose world landmarks ``(..., 33, 3)`` (metres), or ``(..., 33, 4)`` with visibility:
    the points of `BLAZEPOSE_JOINTS` ``(..., K, 3)`` and their weights, `BLAZEPOSE_WEIGHT` times the visibility
    if given (NumPy or JAX)."""
    points = world[..., _BLAZEPOSE_IDS, :]
    return points[..., :3], (points[..., 3] if world.shape[-1] > 3 else 1.0) * _BLAZEPOSE_WEIGHTS


BODY_IK_JOINTS = tuple(j <= 21 and j not in (20, 21) for j in range(55))  # global + body, wrists left to hands
LEFT_HAND_IK_JOINTS = tuple(j == 20 or 25 <= j < 40 for j in range(55))
RIGHT_HAND_IK_JOINTS = tuple(j == 21 or 40 <= j < 55 for j in range(55))

# Priors toward the start, in metres of landmark error per radian of turn: what joint positions do not see (a
# bone's twist, how a rotation splits between a joint and its neighbours) stays where the start puts it. A radian
# of such turn weighs as a landmark 3 cm off for the body (BlazePose's world landmarks are centimetres off, so any
# turn they do see still follows them; weaker, IK picks each unseen twist afresh in every frame, a foot turned by
# ~100 degrees between frames 1/60 s apart), 0.5 mm for the hand's joints (a hand's landmarks are millimetres
# apart), 5 cm for a finger off its flexion axis and for the thumb (fingers bend as hinges), 20 cm for a finger
# past its range (`least_squares.BEND_LIMITS`).
IKConfig = functools.partial(least_squares.SolverConfig, iterations=20, linear_solver="cg", cg_iterations=30,
                             prior_global=1e-4,
                             prior_body=0.03, prior_hand=5e-4, prior_finger_hinge=0.05, prior_thumb=0.05,
                             prior_finger_range=0.2, robust_scale=0.2)


def ik_one(km, targets, conf, theta, betas, free_joints, fit_betas, config, prior_pose=None):
    """`ik` of one frame with its keypoint model ``km`` made beforehand; ``free_joints`` (55,) and ``fit_betas``
    as float arrays (traced: one compiled solver serves any free set). The solve starts at ``theta``; the priors
    hold the free joints near ``prior_pose`` (55, 3) (default ``theta``): a solve warm-started from the previous
    frame keeps its priors on a fixed pose, so twists no joint position sees cannot drift from frame to frame."""
    finite = jnp.all(jnp.isfinite(targets), -1)
    conf = jnp.where(finite & (conf > 0), conf, 0.0)
    targets = jnp.where(finite[:, None], targets, 0.0)
    w = conf / jnp.maximum(jnp.sum(conf), 1e-12)
    offset = jnp.sum(w[:, None] * (targets - keypoints_cm(km, theta, betas).T), 0)
    prior = jnp.asarray(least_squares.prior_weights(config), theta.dtype)
    centre = theta if prior_pose is None else jnp.where(free_joints[:, None] > 0, prior_pose, theta)
    problem = least_squares.Problem(km, targets, conf, centre, betas, prior, jnp.ones((), theta.dtype), free_joints,
                                    fit_betas, jnp.zeros((), theta.dtype), jnp.zeros(3, theta.dtype))
    start = least_squares.Unknowns(theta, betas, jnp.concatenate([jnp.zeros(1, theta.dtype), offset]))
    out = levenberg_marquardt.solve(problem, start, config).value
    pose, betas_out = least_squares.pose_and_shape(out, problem)
    cam = jnp.concatenate([jnp.exp(out.camera[:1]), out.camera[1:]])
    ok = (jnp.sum(conf > 0) >= 3) & jnp.all(jnp.isfinite(pose)) & jnp.all(jnp.isfinite(cam))
    return (jnp.where(ok, pose, theta), jnp.where(ok, betas_out, betas),
            jnp.where(ok, cam, jnp.concatenate([jnp.ones(1, theta.dtype), offset])), ok)


@disk_jit(static_argnames="config")
def _ik_batch(km, targets, conf, theta, betas, free_joints, fit_betas, config):
    # The masks are traced: body and hand IK (both 21 keypoints) share one compiled solver.
    one = functools.partial(ik_one, free_joints=free_joints, fit_betas=fit_betas, config=config)
    return jax.vmap(one, in_axes=(None, 0, 0, 0, 0))(km, targets, conf, theta, betas)


def ik(model: BodyModel, index, targets, conf, theta, betas, free_joints, *, fit_betas: bool = False,
       config: least_squares.SolverConfig | None = None):
    """Fit ``theta (T, 55, 3)`` (joints ``free_joints`` free) and optionally ``betas`` so that the model's joints
    ``index`` (into the 127) match ``targets (T, K, 3)`` up to a scale and an offset. Returns
    ``(theta, betas, cam (T, 4) = scale, offset, ok (T,))``; non-finite targets count as missing. Solved in the
    fit's padded batch sizes (`fitting.BUCKETS`): any number of frames reuses a few compiled solvers."""
    km = keypoint_model(model, index)
    free, fit_shape, config = jnp.asarray(free_joints, jnp.float32), jnp.float32(fit_betas), config or IKConfig()
    frames = tuple(np.asarray(a, np.float32) for a in (targets, conf, theta, betas))  # padded in NumPy
    return map_in_buckets(lambda chunk, _: _ik_batch(km, *chunk, free, fit_shape, config), frames, BUCKETS)


TORSO_LANDMARKS = (11, 12, 23, 24)  # BlazePose's shoulders and hips
TORSO_JOINTS = (16, 17, 1, 2)  # SMPL-X's


def torso_orientation(model: BodyModel, world: np.ndarray) -> np.ndarray:
    """``(T, 3)`` axis-angles: the global orientation that turns the torso of `default_pose` (shoulders and hips,
    its own orientation left out) onto BlazePose's world landmarks ``(T, 33, 3+)`` of each frame, by the rotation of
    least squares between the two centred point sets (Kabsch). A frame whose torso is not seen keeps the default's.
    IK starting from upright in image axes turns a body seen askew or lying the shorter way round, which can leave
    it facing backwards; the torso's rotation is the start that holds for any camera's roll."""
    rest_pose = np.asarray(default_pose(np.float32)).copy()
    rest_pose[0] = 0.0
    rest = np.asarray(forward_joints_jit(model, params_of(jnp.asarray(rest_pose), jnp.zeros(model.num_betas,
                                                                                           jnp.float32),
                                                          model.num_expression)))[list(TORSO_JOINTS)]
    rest = rest - rest.mean(0)
    torso = np.asarray(world, np.float64)[:, list(TORSO_LANDMARKS), :3]
    torso = torso - torso.mean(1, keepdims=True)
    u, _, vt = np.linalg.svd(np.einsum("ji,tjk->tik", rest, torso))  # rest^T torso of each frame
    reflect = np.sign(np.linalg.det(u @ vt))
    rotation = np.swapaxes((u * np.stack([np.ones_like(reflect), np.ones_like(reflect), reflect], -1)[:, None])
                           @ vt, 1, 2)  # torso ~ rest @ rotation^T
    rotvecs = Rotation.from_matrix(rotation).as_rotvec().astype(np.float32)
    seen = np.all(np.isfinite(torso), (1, 2)) & (np.linalg.norm(torso, axis=-1).min(1) > 1e-6)
    return np.where(seen[:, None], rotvecs, np.asarray(default_pose())[0])


def body_from_blazepose(model: BodyModel, world: np.ndarray, theta=None, betas=None, config=None):
    """Body pose from BlazePose world landmarks ``(T, 33, 3)`` (or ``(T, 33, 4)`` with visibility as confidence).
    Starts from ``theta`` (default `default_pose` turned by `torso_orientation`); wrists and hands are kept."""
    world = np.asarray(world, np.float32)
    t = world.shape[0]
    targets, conf = blazepose_targets(world)
    conf = np.broadcast_to(conf, targets.shape[:2])
    if theta is None:
        theta = np.broadcast_to(np.asarray(default_pose()), (t, 55, 3)).copy()
        theta[:, 0] = torso_orientation(model, world)
    betas = np.zeros((t, model.num_betas), np.float32) if betas is None else betas
    return ik(model, BLAZEPOSE_JOINTS, targets, conf, theta, betas, BODY_IK_JOINTS, config=config)


def hand_into_body(model: BodyModel, side: str, hand_world: np.ndarray, theta, betas, conf=None, config=None):
    """Wrist and fingers of one side from the hand's 21 3D landmarks ``(T, 21, 3)`` (OpenPose/mediapipe order),
    the rest of the body fixed."""
    index = constants.LEFT_HAND21_FROM_SMPLX if side == "left" else constants.RIGHT_HAND21_FROM_SMPLX
    free = LEFT_HAND_IK_JOINTS if side == "left" else RIGHT_HAND_IK_JOINTS
    hand_world = np.asarray(hand_world, np.float32)
    conf = np.ones(hand_world.shape[:2], np.float32) if conf is None else conf
    return ik(model, index, hand_world[..., :3], conf, theta, betas, free, config=config)
