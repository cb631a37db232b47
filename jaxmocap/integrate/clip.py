"""One person's whole clip as one least-squares problem: every frame's pose and translation, one body shape.

    result = fit_clip(model, keypoints, init, focal_length=f, principal_point=c, fps=60.0,
                      keypoint_sigma_px=sigma, directions=bone_directions, direction_weight=their_confidence)

Unknowns (`ClipUnknowns`): each frame's rotations of the 52 joints a fit moves (`SOLVED_JOINTS`: all but the jaw
and the eyes, which no keypoint sees) and the body's translation in the camera frame (metres; a pinhole camera of
known focal length and principal point), and one ``betas`` for the clip. Every residual (`residuals`) is an error
divided by its standard deviation, stated in its own physical unit (`ClipConfig`), so that the cost is a sum of
squared normalised errors whose balance holds for any video:

* the 67 OpenPose keypoints' reprojection, in pixels over each keypoint's detector noise (``keypoint_sigma_px``),
  by confidence, robust (Cauchy, beyond ``cauchy`` standard deviations);
* the directions of the bones (`BONES`) against the 3D landmarks' (BlazePose's body and hands, in the camera's
  axes), in radians over ``direction_sigma_deg``, by confidence, robust alike (a landmark model's gross errors, a
  hand seen palm for back, count less and less): the depth that one image cannot give;
* anatomy: elbows, knees and fingers within their range (`least_squares.BEND_LIMITS`, radians over
  ``limit_sigma_deg``), fingers bending as hinges (``hinge_sigma_deg``), every joint's rotation from rest over
  ``pose_sigma_deg`` (what no observation decides, a bone's twist, stays near rest);
* motion: the second differences of the 67 keypoints in 3D (root included; a hand's where it is seen) times the
  frame rate squared, in m/s^2 over ``acceleration_sigma``, and of the body joints' rotations, in rad/s^2 over
  ``angular_acceleration_sigma`` (a twist the keypoints hardly see turns smoothly too); a frame's acceleration is
  expected within them at any frame rate;
* the shape: ``betas`` over one standard deviation of the population (the model's shape space is whitened);
* the ground, where a floor is known (`ClipGround`, the scene's frame): a heel or toe carrying weight touches the
  floor (its sole's height over ``contact_height_sigma_m``) and does not move (its velocity, in m/s over
  ``planted_speed_sigma``); no heel or toe sinks below it (the depth below, over the same sigma).

The motion and the ground are the scene's: a camera that turns (``scene_from_camera``, each frame's rotation from
its camera's axes to the scene's, the axes of a camera that does not turn; zero for a static camera) turns about
its own centre, so a point ``X`` of the camera's frame is ``R X`` in the scene's, and the body's orientation ``R G``.

Frames where the person is not ``found`` hold their start and weigh nothing. Solved by `ClipLevenbergMarquardt`
(an `optimistix` least-squares solver, matrix-free: conjugate gradients on the damped Gauss-Newton system of the
robust errors reweighted at each step's start, each product one pass over the clip), preconditioned by
`preconditioner`'s blocks: each frame's body and each of its hands, each with its coupling to the frames beside
it, factored exactly (`banded`). Work and memory are linear in the number of frames. `fit_clip` is pure and
differentiable (implicit differentiation of the optimum).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike, Bool, Float, Int

from jaxmocap.integrate import banded, mat3
from jaxmocap.integrate import keypoints as keypoint_map
from jaxmocap.integrate.clip_solver import ClipLevenbergMarquardt, Step
from jaxmocap.integrate.fitting import openpose_keypoint_model
from jaxmocap.integrate.keypoints import KeypointModel, params_of
from jaxmocap.integrate.least_squares import BEND_LIMITS, FINGER_JOINTS, bend_of, log1p_ratio
from smplx_jax import BodyModel, SMPLXParams
from smplx_jax.constants import BODY25_FROM_SMPLX
from smplx_jax.rotations import quat_product, quat_to_rotvec, rotvec_to_quat, rotvec_to_rotmat

SOLVED_JOINTS = tuple(j for j in range(55) if j not in (22, 23, 24))  # all but the jaw and the eyes
FIXED_JOINTS = (22, 23, 24)

# Bones whose directions the 3D landmarks observe, as pairs of the 67 OpenPose keypoints (BODY_25, then each hand's
# 21): upper arms, forearms, thighs, shins, feet (heel and ankle to big toe), the shoulder and hip lines, the
# torso's sides, the ears' line and each ear to the nose; then each hand's 20 bones (wrist to each finger's base,
# along each finger).
BODY_BONES = ((5, 6), (6, 7), (2, 3), (3, 4), (12, 13), (13, 14), (9, 10), (10, 11), (14, 19), (11, 22), (21, 19),
              (24, 22), (5, 2), (12, 9), (5, 12), (2, 9), (18, 17), (18, 0), (17, 0))
# BlazePose landmark of each BODY_25 keypoint that `BODY_BONES` uses
BLAZEPOSE_OF_BODY25 = {0: 0, 2: 12, 3: 14, 4: 16, 5: 11, 6: 13, 7: 15, 9: 24, 10: 26, 11: 28, 12: 23, 13: 25,
                       14: 27, 17: 8, 18: 7, 19: 31, 21: 29, 22: 32, 24: 30}
HAND_BONES = tuple((0 if k % 4 == 0 else k, k + 1) for k in range(20))  # OpenPose / mediapipe hand order
BONES = BODY_BONES + tuple((25 + a, 25 + b) for a, b in HAND_BONES) + tuple((46 + a, 46 + b) for a, b in HAND_BONES)


@dataclasses.dataclass(frozen=True)
class ClipConfig:
    """Each residual's standard deviation in its unit (module docstring), and the solve's step cap (static)."""

    iterations: int = 60  # the cap on Levenberg-Marquardt steps
    cg_iterations: int = 8  # conjugate-gradient steps for each step's linear system
    cauchy: float = 3.0  # errors beyond this many standard deviations count less and less (Cauchy)
    direction_sigma_deg: float = 15.0  # the 3D landmarks' bone directions
    acceleration_sigma: float = 20.0  # m/s^2: a keypoint's acceleration in one frame
    # rad/s^2: a body joint's angular acceleration in one frame. Human joints reach a few hundred in everyday and
    # sporting motion; a joint turned round between two frames (a twist the keypoints hardly see) is thousands.
    angular_acceleration_sigma: float = 300.0
    pose_sigma_deg: float = 60.0  # each joint's rotation from rest, what no observation decides
    hinge_sigma_deg: float = 10.0  # the fingers (index to ring) off their flexion axis
    limit_sigma_deg: float = 3.0  # beyond a joint's range
    betas_sigma: float = 1.0  # standard deviations of the shape space
    # metres: a sole carrying weight off the floor's plane (the floor's unevenness, a shoe's sole pressed, the heel's
    # or toe's point on the sole shifting as the foot rolls), and how far a heel or toe sinks through it
    contact_height_sigma_m: float = 0.01
    # m/s: a heel or toe carrying weight does not slide; it moves by a few centimetres a second as the foot rolls
    # over it (where it lifts, the contact ends)
    planted_speed_sigma: float = 0.05
    # converged when the decrease the model predicts to the optimum is below this per frame, in the cost's units
    # (half a squared standard error, i.e. the negative log-likelihood): then every frame is within
    # sqrt(2 * 0.1) = 0.45 standard errors of its optimum along the step, well inside what its observations decide
    tolerance_per_frame: float = 0.1


class ClipUnknowns(NamedTuple):
    """What `fit_clip` solves for: ``T`` frames of `SOLVED_JOINTS` rotations and translations, one shape."""

    pose_rotvecs: Float[Array, "T 52 3"]  # axis-angles, SMPL-X's joints of SOLVED_JOINTS
    transl: Float[Array, "T 3"]  # the body's origin in the camera frame, metres
    betas: Float[Array, "B"]


FOOT_JOINTS = (62, 60, 65, 63)  # left heel, left big toe, right heel, right big toe (SMPL-X's vertex joints)
FOOT_KEYPOINTS = tuple(BODY25_FROM_SMPLX.index(joint) for joint in FOOT_JOINTS)  # the same of BODY_25


class ClipGround(NamedTuple):
    """The floor of a clip fit and which feet carry weight on it (all arrays: one compiled solver serves clips with
    and without one): ``floor (4,)`` the plane ``n · X + d = 0`` in the scene's frame (``(nx, ny, nz, d)``, ``n``
    the unit up direction), ``above_sole (4,)`` each of `FOOT_KEYPOINTS`' height above its sole with the foot flat
    (metres), ``contact (T, 4)`` 1 where that heel or toe carries weight, ``known`` 1 where there is a floor (0: no
    ground residual)."""

    floor: Float[Array, "4"]
    above_sole: Float[Array, "4"]
    contact: Float[Array, "T 4"]
    known: Float[Array, ""]

    @classmethod
    def none(cls, frames: int, dtype=jnp.float32) -> "ClipGround":
        """No floor (``known`` 0) over ``frames`` frames."""
        return cls(jnp.zeros(4, dtype), jnp.zeros(4, dtype), jnp.zeros((frames, 4), dtype), jnp.zeros((), dtype))


class ClipData(NamedTuple):
    """The observations and constants of one clip (`fit_clip` builds it; all arrays, so one compiled solver
    serves any clip of the same length)."""

    km: KeypointModel
    target: Float[Array, "T 67 2"]  # pixels
    confidence: Float[Array, "T 67"]  # 0: missing
    sigma: Float[Array, "T 67"]  # pixels
    directions: Float[Array, "T N 3"]  # unit, camera axes
    direction_weight: Float[Array, "T N"]  # 0: missing
    found: Float[Array, "T"]  # 1 where the person was found
    start: ClipUnknowns  # what frames without the person hold
    fixed_pose: Float[Array, "T 3 3"]  # the jaw and eyes
    focal_length: Float[Array, ""]
    principal_point: Float[Array, "2"]
    fps: Float[Array, ""]
    fit_betas: Float[Array, ""]  # 1: the shape is solved for; 0: it holds the start's
    ground: ClipGround
    scene_from_camera: Float[Array, "T 3"]  # axis-angles: each frame's camera axes turned into the scene's


class ClipResiduals(NamedTuple):
    """`residuals` by structure: ``frames`` depend on their frame's unknowns (and the shape), ``motion[t]`` on
    frames ``t - 1 .. t + 1``, ``shared`` on the shape alone (`preconditioner`'s blocks follow it)."""

    frames: Float[Array, "T F"]
    motion: Float[Array, "T M"]
    shared: Float[Array, "B"]


class ClipResult(NamedTuple):
    """`fit_clip`'s result: ``params`` (T leading; ``transl`` the body's origin in the camera frame, one
    ``betas`` in every row), whether the solve ``converged`` (met its stopping rule, not its step cap), its
    ``steps``, and each frame's mean reprojection error (pixels, over the keypoints with confidence > 0)."""

    params: SMPLXParams
    converged: Bool[Array, ""]
    steps: Int[Array, ""]
    reprojection_error_px: Float[Array, "T"]


def full_pose(pose: Float[Array, "52 3"], fixed: Float[Array, "3 3"]) -> Float[Array, "55 3"]:
    """The 55 joints' rotations from `SOLVED_JOINTS`' and the jaw's and eyes'."""
    return jnp.concatenate([pose[:22], fixed, pose[22:]])


def prior_sigma_rad(config: ClipConfig) -> np.ndarray:
    """``(55, 3)`` the standard deviation of each joint's rotation from rest (radians; inf: no prior):
    none for the global orientation, ``pose_sigma_deg`` for the rest, ``hinge_sigma_deg`` for the index to ring
    fingers' twist about the bone (x in the rest pose) and sideways bending (y) but at the knuckle."""
    sigma = np.full((55, 3), np.radians(config.pose_sigma_deg))
    sigma[0] = np.inf
    for first in (25, 40):
        fingers = first + np.asarray(FINGER_JOINTS)
        sigma[fingers, 0] = np.radians(config.hinge_sigma_deg)
        sigma[fingers[np.asarray(FINGER_JOINTS) % 3 > 0], 1] = np.radians(config.hinge_sigma_deg)
    return sigma


def points_3d(km: KeypointModel, pose: Float[Array, "55 3"], betas, transl) -> Float[Array, "67 3"]:
    """The 67 keypoints in the camera frame, metres."""
    return keypoint_map.keypoints_cm(km, pose, betas).T + transl


def _pixels(x: Float[Array, "... 3"], data: ClipData) -> Float[Array, "... 2"]:
    return data.focal_length * x[..., :2] / jnp.maximum(x[..., 2:], 1e-3) + data.principal_point


def _bones(x: Float[Array, "... 67 3"]) -> tuple[Float[Array, "... N 3"], Float[Array, "... N"]]:
    """Each of `BONES`' unit direction and length."""
    a, b = (np.asarray(side) for side in zip(*BONES))
    bone = x[..., b, :] - x[..., a, :]
    length = jnp.sqrt(jnp.maximum(jnp.sum(bone * bone, -1), 1e-12))
    return bone / length[..., None], length


def shape_of(y: ClipUnknowns, data: ClipData) -> Float[Array, "B"]:
    """The clip's ``betas``: the unknowns' where the shape is solved for, else the start's."""
    return jnp.where(data.fit_betas > 0, y.betas, data.start.betas)


def keypoints_3d(y: ClipUnknowns, data: ClipData) -> Float[Array, "T 67 3"]:
    """Every frame's 67 keypoints in the camera frame, metres."""
    betas = shape_of(y, data)
    return jax.vmap(lambda p, f, t: points_3d(data.km, full_pose(p, f), betas, t))(y.pose_rotvecs, data.fixed_pose,
                                                                                  y.transl)


def motion_rows(data: ClipData) -> Float[Array, "T 67"]:
    """1 where a keypoint's acceleration is a residual: its part (the body, or its hand: any of the hand's keypoints
    seen) is there in the frame and both its neighbours. Unseen, a hand's fingers hold their start, not the arm's
    swing."""
    hands = [jnp.any(data.confidence[:, part] > 0, -1) for part in (slice(25, 46), slice(46, 67))]
    there = data.found[:, None] * jnp.concatenate(
        [jnp.ones((data.found.shape[0], 25), data.found.dtype)]
        + [jnp.repeat(seen[:, None], 21, 1).astype(data.found.dtype) for seen in hands], 1)
    if there.shape[0] < 3:
        return jnp.zeros_like(there)
    zero = jnp.zeros_like(there[:1])
    return jnp.concatenate([zero, there[:-2] * there[1:-1] * there[2:], zero])


def _observed_errors(x: Float[Array, "T 67 3"], data: ClipData, config: ClipConfig):
    """The keypoints' reprojection errors and the bones' direction errors, each over its standard deviation."""
    error = (_pixels(x, data) - data.target) / data.sigma[..., None]
    off = (_bones(x)[0] - data.directions) / np.radians(config.direction_sigma_deg)
    return error, off


def _cauchy_weights(x: Float[Array, "T 67 3"], data: ClipData, config: ClipConfig
                    ) -> tuple[Float[Array, "T 67"], Float[Array, "T N"]]:
    """Cauchy's weight ``1 / (1 + u)`` of each keypoint's reprojection and each bone's direction at the points
    ``x`` (what iteratively reweighted steps and `preconditioner` weigh each error by)."""
    return tuple(1.0 / (1.0 + jnp.sum(e * e, -1) / config.cauchy**2) for e in _observed_errors(x, data, config))


def residuals(y: ClipUnknowns, data: ClipData, config: ClipConfig,
              weighed_at: ClipUnknowns | None = None) -> ClipResiduals:
    """Every residual of the clip (module docstring); half their sum of squares is the cost `fit_clip`
    minimises. With ``weighed_at``, the robust errors are each scaled by Cauchy's weight at ``weighed_at``
    instead (``1 / sqrt(1 + u)``, iteratively reweighted least squares): at ``y = weighed_at`` the gradient of
    half their sum of squares is the cost's, and its Gauss-Newton matrix is the reweighted one (`preconditioner`'s),
    which models the cost far better than the Jacobian of Cauchy's square root, flat along an outlier's error."""
    x = keypoints_3d(y, data)
    error, off = _observed_errors(x, data, config)
    if weighed_at is None:
        u, v = (jnp.sum(e * e, -1) / config.cauchy**2 for e in (error, off))
        robust = [jnp.sqrt(log1p_ratio(u)), jnp.sqrt(log1p_ratio(v))]
    else:
        robust = [jnp.sqrt(w) for w in _cauchy_weights(keypoints_3d(weighed_at, data), data, config)]
    weight = jnp.sqrt(data.confidence * data.found[:, None])
    reprojection = (weight * robust[0])[..., None] * error
    direction = (jnp.sqrt(data.direction_weight * data.found[:, None]) * robust[1])[..., None] * off
    pose = jax.vmap(full_pose)(y.pose_rotvecs, data.fixed_pose)
    limits = jax.nn.relu(jax.vmap(bend_of)(pose)) / np.radians(config.limit_sigma_deg)
    prior = y.pose_rotvecs / prior_sigma_rad(config)[list(SOLVED_JOINTS)]
    lost = 1.0 - data.found
    hold = jnp.concatenate([lost[:, None, None] * (y.pose_rotvecs - data.start.pose_rotvecs),
                            lost[:, None, None] * (y.transl - data.start.transl)[:, None]], 1)
    t = x.shape[0]
    shared = jnp.where(data.fit_betas > 0, y.betas / config.betas_sigma, y.betas - data.start.betas)
    touching, sinking, sliding = ground_residuals(x, data, config)
    frames = jnp.concatenate([reprojection.reshape(t, -1), direction.reshape(t, -1), limits, prior.reshape(t, -1),
                              hold.reshape(t, -1), touching, sinking], 1)
    motion = motion_residuals(x, y.pose_rotvecs, motion_rows(data), data.fps, config, data.scene_from_camera)
    return ClipResiduals(frames, jnp.concatenate([motion, sliding.reshape(t, -1)], 1), shared)


def contact_weights(data: ClipData) -> tuple[Float[Array, "T 4"], Float[Array, "T 4"], Float[Array, "T 4"]]:
    """Where each of `FOOT_KEYPOINTS` touches the floor, where it may not sink below it (elsewhere on a known
    floor), and where it stays put from one frame to the next (in contact in both; zero in the last frame), in the
    frames where the person is found."""
    ground, found = data.ground, data.found[:, None]
    touching = ground.known * ground.contact * found
    free = ground.known * (1.0 - ground.contact) * found
    planted = jnp.concatenate([touching[:-1] * touching[1:], jnp.zeros_like(touching[:1])])
    return touching, free, planted


def floor_normals(data: ClipData) -> Float[Array, "T 3"]:
    """The floor's up direction in each frame's camera axes."""
    return jnp.einsum("tji,j->ti", rotvec_to_rotmat(data.scene_from_camera), data.ground.floor[:3])


def heights_above_floor(x: Float[Array, "T 67 3"], data: ClipData) -> Float[Array, "T 4"]:
    """How far each of `FOOT_KEYPOINTS`' soles (``x`` in the camera frame) is above the floor (metres; negative
    below it), the foot flat."""
    return (jnp.einsum("tkc,tc->tk", x[:, FOOT_KEYPOINTS], floor_normals(data)) + data.ground.floor[3]
            - data.ground.above_sole)


def ground_residuals(x: Float[Array, "T 67 3"], data: ClipData, config: ClipConfig
                     ) -> tuple[Float[Array, "T 4"], Float[Array, "T 4"], Float[Array, "T 4 3"]]:
    """The ground's residuals (module docstring): each heel's and toe's sole height where it touches the floor, its
    depth below the floor elsewhere, its velocity in the scene (to the next frame, m/s) where it is planted, each
    over its sigma."""
    touching, free, planted = contact_weights(data)
    height = heights_above_floor(x, data) / config.contact_height_sigma_m
    feet = jnp.einsum("tij,tkj->tki", rotvec_to_rotmat(data.scene_from_camera), x[:, FOOT_KEYPOINTS])
    velocity = jnp.concatenate([feet[1:] - feet[:-1], jnp.zeros_like(feet[:1])]) * data.fps
    return (touching * height, free * jax.nn.relu(-height),
            planted[..., None] * velocity / config.planted_speed_sigma)


def in_scene(x: Float[Array, "T K 3"], pose_rotvecs: Float[Array, "T J 3"], scene_from_camera: Float[Array, "T 3"]
             ) -> tuple[Float[Array, "T K 3"], Float[Array, "T J 3"]]:
    """The keypoints ``x`` (camera frame) and the rotations ``pose_rotvecs`` (the global orientation first) in the
    scene's axes (module docstring)."""
    q = rotvec_to_quat(scene_from_camera)
    root = quat_to_rotvec(quat_product(q, rotvec_to_quat(pose_rotvecs[:, 0])))
    return (jnp.einsum("tij,tkj->tki", rotvec_to_rotmat(scene_from_camera), x),
            jnp.concatenate([root[:, None], pose_rotvecs[:, 1:]], 1))


def motion_residuals(x: Float[Array, "T K 3"], pose_rotvecs: Float[Array, "T J 3"], rows: Float[Array, "T K"],
                     fps, config: ClipConfig, scene_from_camera: Float[Array, "T 3"] | None = None
                     ) -> Float[Array, "T M"]:
    """The motion's residuals (module docstring) of the keypoints ``x`` (camera frame) and the body joints'
    rotations (the first `BODY` of ``pose_rotvecs``), in the scene's axes (`in_scene`; None: the camera's), each
    frame's where ``rows`` (`motion_rows`) says; zero in the first and last. The angular accelerations count where a
    frame's first keypoint's row does (the body's, or a hand's own)."""
    pose_rotvecs = pose_rotvecs[:, :BODY]
    if scene_from_camera is not None:
        x, pose_rotvecs = in_scene(x, pose_rotvecs, scene_from_camera)
    t = x.shape[0]
    acceleration = (jnp.concatenate([jnp.zeros_like(x[:1]), x[:-2] - 2 * x[1:-1] + x[2:], jnp.zeros_like(x[:1])])
                    if t > 2 else jnp.zeros_like(x)) * fps**2
    motion = rows[..., None] * acceleration / config.acceleration_sigma
    angular = rows[:, :1, None] * _angular_accelerations(pose_rotvecs) * fps**2 / (
        config.angular_acceleration_sigma)
    return jnp.concatenate([motion.reshape(t, -1), angular.reshape(t, -1)], 1)


def _angular_accelerations(rotvecs: Float[Array, "T J 3"]) -> Float[Array, "T J 3"]:
    """The second differences of each joint's rotation (radians per frame squared; zero in the first and last
    frames): the change between one frame's turn to the next and the previous one's, each turn ``log(R_t^T
    R_t+1)`` in the joint's own axes."""
    if rotvecs.shape[0] < 3:
        return jnp.zeros_like(rotvecs)
    q = rotvec_to_quat(rotvecs)
    turns = quat_to_rotvec(quat_product(q[:-1] * jnp.asarray([1.0, -1.0, -1.0, -1.0], q.dtype), q[1:]))
    zero = jnp.zeros_like(rotvecs[:1])
    return jnp.concatenate([zero, turns[1:] - turns[:-1], zero])


BODY = 22  # the body's joints (global orientation to wrists), the first of SOLVED_JOINTS


class ClipBlocks(NamedTuple):
    """`preconditioner`'s blocks of ``J^T J``: the bodies' (each frame's 22 joints' increments, then its
    translation) and each hand's (its 15 joints' increments), each with its coupling over time (block-banded); the
    shape's diagonal (`clip_solver.Preconditioner`)."""

    body: banded.Banded  # m = 69
    hands: tuple[banded.Banded, banded.Banded]  # left, right: m = 45
    betas: Float[Array, "B"]

    def diagonal(self) -> Step:
        body = jnp.diagonal(self.body.diagonal, axis1=-2, axis2=-1)
        hands = [jnp.diagonal(hand.diagonal, axis1=-2, axis2=-1).reshape(-1, 15, 3) for hand in self.hands]
        return Step(jnp.concatenate([body[:, :3 * BODY].reshape(-1, BODY, 3), *hands], 1), body[:, 3 * BODY:],
                    self.betas)

    def damped_inverse(self, shift: Step) -> Callable[[Step], Step]:
        frames = shift.pose.shape[0]

        def body_of(step):
            return jnp.concatenate([step.pose[:, :BODY].reshape(frames, -1), step.transl], 1)

        def hand_of(step, h):
            return step.pose[:, BODY + 15 * h:BODY + 15 * (h + 1)].reshape(frames, 45)

        shifted = [blocks._replace(diagonal=blocks.diagonal + jax.vmap(jnp.diag)(rows)) for blocks, rows in
                   zip((self.body, *self.hands), (body_of(shift), hand_of(shift, 0), hand_of(shift, 1)))]
        factors = banded.factor(shifted)
        betas = 1.0 / (self.betas + shift.betas)

        def apply(v: Step) -> Step:
            solved, *fingers = banded.solve(factors, (body_of(v), hand_of(v, 0), hand_of(v, 1)))
            pose = jnp.concatenate([solved[:, :3 * BODY].reshape(frames, BODY, 3),
                                    *(f.reshape(frames, 15, 3) for f in fingers)], 1)
            return Step(pose, solved[:, 3 * BODY:], betas * v.betas)

        return apply


def inverse3(m: Float[Array, "... 3 3"]) -> Float[Array, "... 3 3"]:
    """The inverses of 3x3 matrices (`mat3.inverse`: cofactors, no LAPACK)."""
    columns = jnp.moveaxis(m.reshape(-1, 3, 3), 0, -1)
    return jnp.moveaxis(mat3.inverse(columns), -1, 0).reshape(m.shape)


# The body joints that move each hand (left, right): the kinematic chain from the pelvis to its wrist. A hand's
# keypoints and bones depend on these alone of the body's, so their share of the body's block is a 27 x 27 block
# (these joints' increments and the translation), not 69 x 69.
ARM_CHAINS = ((0, 3, 6, 9, 13, 16, 18, 20), (0, 3, 6, 9, 14, 17, 19, 21))
ARM_COLUMNS = tuple(np.concatenate([(3 * np.asarray(chain)[:, None] + np.arange(3)).ravel(), 3 * BODY + np.arange(3)])
                    for chain in ARM_CHAINS)


def _place(hand: int, dtype) -> Float[Array, "27 69"]:
    """Which of the body's increments each of a hand's `ARM_COLUMNS` is (one-hot rows)."""
    return jnp.asarray(np.eye(3 * BODY + 3)[ARM_COLUMNS[hand]], dtype)


def _spread(block: Float[Array, "... 27 27"], hand: int) -> Float[Array, "... 69 69"]:
    """A hand's arm block (`ARM_COLUMNS`) in the body's."""
    place = _place(hand, block.dtype)
    return jnp.swapaxes(place, 0, 1) @ block @ place


def _products(a: Float[Array, "... n k"], b: Float[Array, "... k m"]) -> Float[Array, "... n m"]:
    """``a @ b`` of stacks of small matrices, written out as sums of products: as batched dots of three batch
    dimensions (a stack, a window's frames, the windows solved together) XLA's GPU compiler fails on some of them
    (jax 0.11.2: the HLO verifier finds the dot's shape permuted)."""
    return jnp.sum(a[..., :, :, None] * b[..., None, :, :], -2)


def _gram(j: Float[Array, "K 3 m"], metric: Float[Array, "K 3 3"]) -> Float[Array, "m m"]:
    """``sum_k J_k^T metric_k J_k``."""
    return jnp.einsum("kci,kcj->ij", j, _products(metric, j))


def _frame_blocks(km, lin, image, motion, bone_metric, axis_weight, to_theta, lost):
    """One frame's diagonal blocks (the body's, each hand's) and its keypoints' Jacobians in the body's increments
    (BODY_25's; each hand's in its `ARM_COLUMNS`) and in each hand's (what couples the frames): ``image`` and
    ``motion`` (K, 3, 3) each keypoint's metric of its 3D position's change (reprojection through the pinhole,
    acceleration's diagonal), ``bone_metric`` (N, 3, 3) each of `BONES`' of the change of its far end relative to
    its near end, ``axis_weight`` (55, 3) the priors' weights on the axis-angles and ``to_theta`` (55, 3, 3) their
    change per local increment."""
    jacobian = keypoint_map.pose_jacobian(km, lin)  # (3, K, 55, 3), in the local increments
    k = jacobian.shape[1]
    body = jnp.concatenate([jnp.moveaxis(jacobian[:, :, :BODY], 0, 1).reshape(k, 3, 3 * BODY),
                            jnp.broadcast_to(jnp.eye(3, dtype=jacobian.dtype), (k, 3, 3))], -1)  # (K, 3, 69)
    metric = image + motion
    theta = _products(jnp.swapaxes(to_theta, -1, -2), axis_weight[..., None] * to_theta)  # (55, 3, 3)
    a, b = (np.asarray(side) for side in zip(*BODY_BONES))
    dense = (_gram(body[:25], metric[:25]) + _gram(body[b] - body[a], bone_metric[:len(BODY_BONES)])
             + jax.scipy.linalg.block_diag(*theta[:BODY], lost * jnp.eye(3, dtype=body.dtype)))
    hands, parts, arms = [], [], []
    near, far = (np.asarray(side) for side in zip(*HAND_BONES))
    for h in range(2):  # a hand's joints move its own 21 keypoints and 20 bones alone
        rows = np.arange(25 + 21 * h, 46 + 21 * h)
        ends = np.arange(len(BODY_BONES) + 20 * h, len(BODY_BONES) + 20 * h + 20)
        arm = body[rows] @ jnp.swapaxes(_place(h, body.dtype), 0, 1)  # (21, 3, 27): its arm's columns
        block = _gram(arm, metric[rows]) + _gram(arm[far] - arm[near], bone_metric[ends])
        dense = dense + _spread(block, h)
        part = jnp.moveaxis(jacobian[:, rows, 25 + 15 * h:40 + 15 * h], 0, 1).reshape(21, 3, 45)
        hands.append(_gram(part, metric[rows]) + _gram(part[far] - part[near], bone_metric[ends])
                     + jax.scipy.linalg.block_diag(*theta[25 + 15 * h:40 + 15 * h]))
        parts.append(part)
        arms.append(arm)
    return dense, jnp.stack(hands), body[:25], jnp.stack(arms), jnp.stack(parts)


def preconditioner(y: ClipUnknowns, data: ClipData, config: ClipConfig) -> ClipBlocks:
    """Blocks of ``J^T J`` at ``y`` (`ClipBlocks`): of each frame's body, from the keypoints' reprojection
    (through the pinhole's Jacobian, at Cauchy's weight), their accelerations, the bones' directions (at Cauchy's
    weight), the joints' angular accelerations (their turns taken as their increments) and the priors, limits and
    holds, coupled to the frames beside it by the accelerations; of each hand's fingers likewise (their coupling to
    the body left out); the shape's diagonal. Blended skinning is left out (millimetres), and a turning camera's
    turn between neighbouring frames from their coupling (a degree or so); any positive definite blocks make the
    solve converge, these make it fast."""
    betas = shape_of(y, data)
    km = data.km
    pose = jax.vmap(full_pose)(y.pose_rotvecs, data.fixed_pose)
    lin = jax.vmap(lambda p: keypoint_map.in_tangent(keypoint_map.linearize(km, p, betas)))(pose)
    x = jnp.swapaxes(lin.x, 1, 2) + y.transl[:, None]  # (T, 67, 3) camera frame
    z = jnp.maximum(x[..., 2], 1e-3)
    keypoint_weight, bone_weight = _cauchy_weights(x, data, config)
    irls = data.confidence * data.found[:, None] * keypoint_weight
    zero, one = jnp.zeros_like(z), jnp.ones_like(z)
    projection = (data.focal_length / z)[..., None, None] * jnp.stack(
        [jnp.stack([one, zero, -x[..., 0] / z], -1), jnp.stack([zero, one, -x[..., 1] / z], -1)], -2)  # (T,K,2,3)
    image = (irls / data.sigma**2)[..., None, None] * _products(jnp.swapaxes(projection, -1, -2), projection)
    rows = motion_rows(data)  # (T, K)
    zero = jnp.zeros_like(rows[:1])
    after = jnp.concatenate([rows[1:], zero])  # the next frame's row
    coefficient = after + 4 * rows + jnp.concatenate([zero, rows[:-1]])
    eye = jnp.eye(3, dtype=x.dtype)
    motion = (coefficient * (data.fps**2 / config.acceleration_sigma) ** 2)[..., None, None] * jnp.broadcast_to(
        eye, image.shape)
    # the ground's: a sole's height along the floor's normal, where it touches or sinks; a planted foot's velocity
    touching, free, planted = contact_weights(data)
    normal = floor_normals(data)
    across_floor = (touching + free * (heights_above_floor(x, data) < 0)) / config.contact_height_sigma_m**2
    still = (data.fps / config.planted_speed_sigma) ** 2
    rolling = still * (planted + jnp.concatenate([jnp.zeros_like(planted[:1]), planted[:-1]]))
    motion = motion.at[:, FOOT_KEYPOINTS].add(across_floor[..., None, None] * (normal[:, None, :, None]
                                                                               * normal[:, None, None, :])
                                               + rolling[..., None, None] * eye)
    unit, length = _bones(x)
    weight = (data.direction_weight * data.found[:, None] * bone_weight
              / (np.radians(config.direction_sigma_deg) * length) ** 2)
    bone_metric = weight[..., None, None] * (eye - unit[..., :, None] * unit[..., None, :])
    # the priors, limits and holds act on the axis-angle, which moves by J_l(theta)^-1 per local increment
    to_theta = inverse3(mat3.left_jacobian(pose))  # (T, 55, 3, 3)
    bend_joints, bend_axes = ([limit[i] for limit in BEND_LIMITS] for i in (0, 1))
    bend = jnp.zeros((pose.shape[0], 55, 3), pose.dtype).at[:, bend_joints, bend_axes].add(
        (jax.vmap(bend_of)(pose) > 0) / np.radians(config.limit_sigma_deg) ** 2)
    lost = 1.0 - data.found
    axis_weight = bend + jnp.asarray(prior_sigma_rad(config) ** -2, pose.dtype) + lost[:, None, None]
    bones = tuple(np.asarray(side) for side in zip(*BONES))
    diagonal, hands, jacobian, arm_jacobians, hand_jacobians = jax.vmap(
        _frame_blocks, in_axes=(None, 0, 0, 0, 0, 0, 0, 0))(km, lin, image, motion, bone_metric, axis_weight,
                                                            to_theta, lost)
    # the accelerations couple each frame with the two before and after it (`residuals`' rows, by frame), a planted
    # foot's velocity with the next
    coupling = (data.fps**2 / config.acceleration_sigma) ** 2
    sliding = jnp.zeros_like(rows).at[:, FOOT_KEYPOINTS].set(planted) * jnp.where(
        coupling > 0, still / jnp.maximum(coupling, 1e-30), 0.0)

    def across_one(by, weight, j):  # sum_k weight[t, k] J[t + by, k]^T J[t, k] of each t, zero past the end
        frames, m = j.shape[0], j.shape[-1]
        zero = jnp.zeros((min(by, frames), m, m), j.dtype)
        if frames <= by:
            return zero
        return jnp.concatenate([jnp.einsum("tkci,tk,tkcj->tij", j[by:], weight[:-by], j[:-by]), zero])

    def across(by, weight):  # of the body's increments: BODY_25's keypoints, and each hand's through its arm
        total = across_one(by, weight[:, :25], jacobian)
        for h in range(len(ARM_COLUMNS)):
            block = across_one(by, weight[:, 25 + 21 * h:46 + 21 * h], arm_jacobians[:, h])
            total = total + _spread(block, h)
        return total

    def hand(h):  # its fingers' blocks, coupled over time by its own keypoints' accelerations
        j, part = hand_jacobians[:, h], slice(25 + 21 * h, 46 + 21 * h)
        return banded.Banded(hands[:, h], coupling * across_one(1, -2 * rows[:, part] - 2 * after[:, part], j),
                             coupling * across_one(2, after[:, part], j))

    # the joints' angular accelerations likewise, each joint's turn taken as its increment's (exact on the diagonal)
    turning = (data.fps**2 / config.angular_acceleration_sigma) ** 2 * jnp.diag(
        jnp.concatenate([jnp.ones(3 * BODY), jnp.zeros(3)]).astype(rows.dtype))
    body_rows, body_after = rows[:, 0], after[:, 0]
    diagonal = diagonal + (body_after + 4 * body_rows + jnp.concatenate([zero[:, 0], body_rows[:-1]]))[
        :, None, None] * turning
    body = banded.Banded(diagonal,
                         coupling * across(1, -2 * rows - 2 * after - sliding)
                         + (-2 * body_rows - 2 * body_after)[:, None, None] * turning,
                         coupling * across(2, after) + body_after[:, None, None] * turning)
    far = jnp.zeros_like(image).at[:, bones[1]].add(bone_metric)
    jb = lin.jb.reshape(pose.shape[0], betas.shape[0], 3, -1)  # (T, B, 3, K)
    shape = jnp.einsum("tbck,tkcd,tbdk->b", jb, image + motion + far, jb) + config.betas_sigma**-2
    return ClipBlocks(body, (hand(0), hand(1)), jnp.where(data.fit_betas > 0, shape, 1.0))


def clip_problem(model: BodyModel | KeypointModel, keypoints: Float[ArrayLike, "T 67 3"], init: SMPLXParams, *,
                 focal_length: float | Float[ArrayLike, ""], principal_point: Float[ArrayLike, "2"],
                 fps: float | Float[ArrayLike, ""], keypoint_sigma_px: Float[ArrayLike, "T 67"],
                 directions: Float[ArrayLike, "T N 3"] | None = None,
                 direction_weight: Float[ArrayLike, "T N"] | None = None, found: Bool[ArrayLike, "T"] | None = None,
                 fit_betas: bool | Bool[ArrayLike, ""] = True, ground: ClipGround | None = None,
                 scene_from_camera: Float[ArrayLike, "T 3"] | None = None) -> tuple[ClipUnknowns, ClipData]:
    """The start and the data of `fit_clip`'s problem (its arguments; ``model`` or its OpenPose keypoint model,
    `fitting.openpose_keypoint_model`, already built), for `residuals`, `preconditioner` and `solve_clip`."""
    dtype = init.global_orient.dtype
    t = keypoints.shape[0]
    keypoints = jnp.asarray(keypoints)
    finite = jnp.all(jnp.isfinite(keypoints), -1)
    confidence = jnp.where(finite & (keypoints[..., 2] > 0), keypoints[..., 2], 0.0).astype(dtype)
    target = jnp.where(finite[..., None], keypoints[..., :2], 0.0).astype(dtype)
    found = (jnp.sum(confidence > 0, -1) > 0) if found is None else jnp.asarray(found)
    if directions is None:
        directions = jnp.zeros((t, len(BONES), 3), dtype)
        direction_weight = jnp.zeros((t, len(BONES)), dtype)
    pose = jax.vmap(SMPLXParams.full_pose)(init)
    found_f = found.astype(dtype)
    betas0 = jnp.sum(found_f[:, None] * init.betas, 0) / jnp.maximum(jnp.sum(found_f), 1.0)
    start = ClipUnknowns(pose[:, list(SOLVED_JOINTS)], init.transl.astype(dtype), betas0)
    km = model if isinstance(model, KeypointModel) else openpose_keypoint_model(model)
    data = ClipData(km, target, confidence, jnp.asarray(keypoint_sigma_px, dtype),
                    jnp.asarray(directions, dtype), jnp.asarray(direction_weight, dtype), found_f, start,
                    pose[:, list(FIXED_JOINTS)], jnp.asarray(focal_length, dtype),
                    jnp.asarray(principal_point, dtype), jnp.asarray(fps, dtype),
                    jnp.asarray(fit_betas, dtype),
                    ClipGround.none(t, dtype) if ground is None else jax.tree.map(lambda a: jnp.asarray(a, dtype),
                                                                                  ClipGround(*ground)),
                    jnp.zeros((t, 3), dtype) if scene_from_camera is None else jnp.asarray(scene_from_camera, dtype))
    return start, data


def fit_clip(model: BodyModel, keypoints: Float[ArrayLike, "T 67 3"], init: SMPLXParams, *,
             focal_length: float | Float[ArrayLike, ""], principal_point: Float[ArrayLike, "2"],
             fps: float | Float[ArrayLike, ""],
             keypoint_sigma_px: Float[ArrayLike, "T 67"], directions: Float[ArrayLike, "T N 3"] | None = None,
             direction_weight: Float[ArrayLike, "T N"] | None = None, found: Bool[ArrayLike, "T"] | None = None,
             fit_betas: bool = True, ground: ClipGround | None = None,
             scene_from_camera: Float[ArrayLike, "T 3"] | None = None, config: ClipConfig | None = None,
             adjoint: optx.AbstractAdjoint | None = None) -> ClipResult:
    """Fit one person's clip (module docstring). ``keypoints (T, 67, 3)``: OpenPose BODY_25 and both hands, x, y
    in pixels and a confidence (0, NaN or inf: missing); ``init``: each frame's start (T leading; ``transl`` in the
    camera frame, the start's ``betas`` averaged over the frames found); ``focal_length`` and ``principal_point``
    in pixels; ``fps`` the clip's frame rate; ``keypoint_sigma_px`` each keypoint's detector noise, pixels;
    ``directions`` and ``direction_weight``: the observed unit direction of each of `BONES` in the camera's axes
    and its confidence (None: no 3D observation); ``found``: where the person is (default: where any keypoint
    is); ``fit_betas`` False holds the shape at the start's; ``ground`` the floor and the feet's contacts
    (`ClipGround`, the scene's frame; None: no floor); ``scene_from_camera`` each frame's camera axes turned into
    the scene's, axis-angles (None: a static camera, the scene's axes the camera's).

    Pure: works under `jax.jit` (one program per clip length) and `jax.grad`; gradients with respect to the
    observations come from implicit differentiation of the optimum (``adjoint`` None, `optimistix.ImplicitAdjoint`:
    it materialises the Jacobian of the optimality condition, fine for short clips;
    ``optimistix.RecursiveCheckpointAdjoint()`` differentiates the steps instead). Matrix products in full float32
    on every device, as `fitting.fit_one`'s."""
    problem = clip_problem(model, keypoints, init, focal_length=focal_length, principal_point=principal_point, fps=fps,
                           keypoint_sigma_px=keypoint_sigma_px, directions=directions,
                           direction_weight=direction_weight, found=found, fit_betas=fit_betas, ground=ground,
                           scene_from_camera=scene_from_camera)
    return solve_clip(*problem, shape_moves=fit_betas, num_expression=model.num_expression, config=config,
                      adjoint=adjoint)


def solve_clip(start: ClipUnknowns, data: ClipData, *, shape_moves: bool, num_expression: int,
               config: ClipConfig | None = None, adjoint: optx.AbstractAdjoint | None = None) -> ClipResult:
    """`fit_clip` of the problem `clip_problem` gave (``num_expression`` the model's): what a compiled caller that
    holds the keypoint model calls. ``shape_moves`` False: the solver never moves the shape (one unknown fewer);
    True: it solves for it where ``data.fit_betas`` says (a traced choice)."""
    config = config or ClipConfig()
    adjoint = optx.ImplicitAdjoint() if adjoint is None else adjoint
    with jax.default_matmul_precision("highest"):
        solver = ClipLevenbergMarquardt(
            tolerance=config.tolerance_per_frame * jnp.maximum(jnp.sum(data.found), 1.0),
            fit_shared=shape_moves, cg_iterations=config.cg_iterations)
        cost = jax.tree_util.Partial(residuals, config=config)
        options = dict(preconditioner=jax.tree_util.Partial(preconditioner, config=config), reweighted=cost)
        solution = optx.least_squares(cost, solver, start, data, options=options, max_steps=config.iterations,
                                      throw=False, adjoint=adjoint)
        y = solution.value
        betas = shape_of(y, data)
        params = jax.vmap(params_of, in_axes=(0, None, None))(
            jax.vmap(full_pose)(y.pose_rotvecs, data.fixed_pose), betas, num_expression)
        return ClipResult(params.replace(transl=y.transl), solution.result == optx.RESULTS.successful,
                          solution.stats["num_steps"], reprojection_errors(y._replace(betas=betas), data))


def reprojection_errors(y: ClipUnknowns, data: ClipData) -> Float[Array, "T"]:
    """Each frame's mean pixel distance between the keypoints projected and their targets (confidence > 0)."""
    def one(pose, fixed, transl, target, confidence):
        pixels = _pixels(points_3d(data.km, full_pose(pose, fixed), y.betas, transl), data)
        seen = confidence > 0
        error = jnp.linalg.norm(pixels - target, axis=-1)
        return jnp.sum(jnp.where(seen, error, 0.0)) / jnp.maximum(jnp.sum(seen), 1)

    return jax.vmap(one)(y.pose_rotvecs, data.fixed_pose, y.transl, data.target, data.confidence)
