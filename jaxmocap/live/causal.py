"""The live path's solve of each person in each frame, causal: IK warm-started from the person's previous frame
(its priors on the rest pose, as offline: a warm start is where the solve begins, not where it is held), then a
few steps of the offline clip fit's objective (`integrate.clip`: the same residuals in the same units) over a
window of the person's last `PAST` frames and this one, solved together from their last estimates: the motion
term ties this frame to them, so that the live motion is smoothed as the offline one, without a filter's lag.
One compiled call per person and frame (`step`), on the host's CPU (`host`)."""

from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

import smplx_jax
from jaxmocap.compile_cache import disk_jit
from jaxmocap.integrate.clip import BONES, ClipConfig, clip_problem, solve_clip
from jaxmocap.integrate.fitting import default_pose, openpose_keypoint_model
from jaxmocap.integrate.inverse_kinematics import (
    BLAZEPOSE_JOINTS,
    BODY_IK_JOINTS,
    LEFT_HAND_IK_JOINTS,
    RIGHT_HAND_IK_JOINTS,
    IKConfig,
    blazepose_targets,
    ik_one,
)
from jaxmocap.integrate.keypoints import KeypointModel, keypoint_model, params_of
from jaxmocap.pipeline.observe import Observations
from jaxmocap.pipeline.stages import Lens, placed
from jaxmocap.pipeline.whole_clip import bone_directions, keypoint_noise_px, weak_camera
from smplx_jax import constants

# The frames before this one in its window: two, as far as an acceleration (the motion term) reaches back. They are
# solved again with it, each on its own observations: held as they were shown, trusted exactly, they would let a
# robust fit follow their extrapolation away from the keypoints (measured: hundreds of pixels within a second).
PAST = 2


@dataclass(frozen=True)
class LiveSettings:
    """How much each frame solves: ``ik_iterations`` of the IK, then the clip fit (``fit``: its residuals' units as
    offline; the steps and conjugate-gradient iterations a frame affords). The shape is solved for with each
    frame's window over the person's first ``shape_settle`` seconds, their mean then held. A person unseen for
    more than ``reset_after`` seconds starts afresh (their shape kept), with ``warm_up`` steps on their first
    frame. ``hands``: the hands' IK runs (not with ``--mode body``: the hands stay flat)."""

    hands: bool = True
    ik_iterations: int = 5
    fit: ClipConfig = ClipConfig(iterations=5, cg_iterations=4)
    shape_settle: float = 1.0
    reset_after: float = 0.5
    warm_up: int = 4


class PersonState(NamedTuple):
    """What a person carries to their next frame: the last IK pose and shape (the next start), the estimates of the
    `PAST` frames before it (oldest first; ``past_found`` 0 where there was none) with their observations, and the
    shape (the mean over ``shape_seconds`` of frames)."""

    theta: Float[Array, "55 3"]
    betas: Float[Array, "B"]
    past_pose: Float[Array, "P 55 3"]
    past_transl: Float[Array, "P 3"]
    past_keypoints: Float[Array, "P 67 3"]
    past_sigma: Float[Array, "P 67"]
    past_directions: Float[Array, "P N 3"]
    past_direction_weight: Float[Array, "P N"]
    past_found: Float[Array, "P"]
    shape: Float[Array, "B"]
    shape_seconds: Float[Array, ""]


class Solved(NamedTuple):
    """One person's body in one frame (``transl`` in the pinhole camera's frame) and the weak-perspective camera
    closest to it; ``valid``: the solve gave finite values."""

    params: smplx_jax.SMPLXParams
    camera_scale: Float[Array, ""]
    camera_trans: Float[Array, "2"]
    valid: Bool[Array, ""]


class Models(NamedTuple):
    """The keypoint models of a step: BlazePose's joints, the hands' 21 (the left's and the right's stacked on a
    leading axis of 2: one vmapped IK solves both), OpenPose's 67."""

    body: KeypointModel
    hands: KeypointModel
    openpose: KeypointModel


def fresh_state(num_betas: int) -> PersonState:
    """The state of a person not seen before: the fit's default pose, mean shape, nothing solved before, no shape
    yet."""
    theta = default_pose()
    betas = jnp.zeros(num_betas, jnp.float32)
    return PersonState(theta, betas, jnp.broadcast_to(theta, (PAST, 55, 3)), jnp.zeros((PAST, 3)),
                       jnp.zeros((PAST, 67, 3)), jnp.ones((PAST, 67)), jnp.zeros((PAST, len(BONES), 3)),
                       jnp.zeros((PAST, len(BONES))), jnp.zeros(PAST), betas, jnp.zeros(()))


def host() -> jax.Device:
    """Where the live path solves: the host's CPU, also beside a GPU. One frame's solve is a few hundred small
    operations in short loops, bound by each operation's launch, not its work, which a GPU's launches make slower
    than its host's CPU (docs/BENCHMARKS.md, "Live")."""
    return jax.devices("cpu")[0]


_BODY_MASK = jnp.asarray(BODY_IK_JOINTS, jnp.float32)
_HAND_MASKS = jnp.asarray([LEFT_HAND_IK_JOINTS, RIGHT_HAND_IK_JOINTS], jnp.float32)  # (2, 55)


@disk_jit(static_argnames=("num_expression", "settings"))
def step(models: Models, obs: tuple, state: PersonState, fresh: Bool[Array, ""], dt: Float[Array, ""], lens: tuple,
         num_expression: int, settings: LiveSettings) -> tuple[Solved, PersonState]:
    """One person's frame: ``obs`` = (BlazePose world landmarks (33, 4), hand world landmarks (2, 21, 3), hand
    presence (2,), OpenPose keypoints (67, 3), their noise in pixels (67,), the bones' observed directions (N, 3)
    and confidence (N,): `whole_clip.keypoint_noise_px`, `whole_clip.bone_directions`); ``fresh``: nothing before
    this frame counts; ``dt``: seconds since the person's last frame (the window's frame rate is ``1 / dt``);
    ``lens``: (focal length, principal point)."""
    world, hands_world, hands_conf, keypoints, sigma, directions, direction_weight = obs
    focal, centre = lens
    ik_config = IKConfig(iterations=settings.ik_iterations)
    targets, conf = blazepose_targets(world)
    rest = default_pose()  # the priors' centre, as in the offline IK (`body_from_blazepose`, `hand_into_body`)
    theta, betas, _, _ = ik_one(models.body, targets, conf, state.theta, state.betas, _BODY_MASK, 0.0, ik_config,
                                rest)
    if settings.hands:  # each hand's wrist and fingers, from the body's pose (the two free sets are disjoint)
        seen = jnp.repeat(jnp.where(hands_conf > 0, 1.0, 0.0)[:, None], 21, 1)
        sides = jax.vmap(lambda km, world, seen, mask: ik_one(km, world, seen, theta, betas, mask, 0.0, ik_config,
                                                              rest)[0])(models.hands, hands_world, seen, _HAND_MASKS)
        for side, mask in enumerate(_HAND_MASKS):
            theta = jnp.where(mask[:, None] > 0, sides[side], theta)
    settled = state.shape_seconds >= settings.shape_settle
    shape = jnp.where(state.shape_seconds > 0, state.shape, betas)  # the window's start
    window = jax.vmap(params_of, in_axes=(0, None, None))(jnp.concatenate([state.past_pose, theta[None]]), shape,
                                                         num_expression)
    start = placed(models.openpose, jax.tree.map(lambda a: a[-1:], window), keypoints[None], focal, centre)[0]
    window = window.replace(transl=jnp.concatenate([state.past_transl, start.transl]))
    past_found = jnp.where(fresh, 0.0, state.past_found)

    def with_past(past, new):
        return jnp.concatenate([past, new[None]])

    problem = clip_problem(models.openpose, with_past(state.past_keypoints, keypoints), window, focal_length=focal,
                           principal_point=centre, fps=1.0 / dt, keypoint_sigma_px=with_past(state.past_sigma, sigma),
                           directions=with_past(state.past_directions, directions),
                           direction_weight=with_past(state.past_direction_weight, direction_weight),
                           found=jnp.append(past_found > 0, True), fit_betas=~settled)
    solved = solve_clip(*problem, shape_moves=True, num_expression=num_expression, config=settings.fit)
    p = jax.tree.map(lambda a: a[-1], solved.params)
    valid = jnp.all(jnp.isfinite(p.full_pose())) & jnp.all(jnp.isfinite(p.transl))
    scale, trans = weak_camera(models.openpose, p, focal, centre, keypoints[:, 2])
    weight = jnp.where(fresh | settled, 0.0, jnp.minimum(dt, 0.1))  # seconds this frame adds to the shape's mean
    seconds = state.shape_seconds + weight
    mean = (state.shape * state.shape_seconds + p.betas * weight) / jnp.maximum(seconds, 1e-6)
    shape = jnp.where(settled, state.shape, jnp.where(seconds > 0, mean, p.betas))

    def shifted(past, new):
        return with_past(past, new)[1:]

    new = PersonState(theta, betas, jax.vmap(smplx_jax.SMPLXParams.full_pose)(solved.params)[1:],
                      solved.params.transl[1:], shifted(state.past_keypoints, keypoints),
                      shifted(state.past_sigma, sigma), shifted(state.past_directions, directions),
                      shifted(state.past_direction_weight, direction_weight), shifted(past_found, jnp.ones(())),
                      shape, seconds)
    new = jax.tree.map(lambda a, b: jnp.where(valid, a, b), new, state)
    return Solved(p.replace(betas=shape), scale, trans, valid), new


class CausalSolver:
    """Each person's `step`, frame after frame, with their state kept by identity."""

    def __init__(self, model: smplx_jax.BodyModel, lens: Lens, settings: LiveSettings = LiveSettings()):
        self.device = host()
        hands = jax.tree.map(lambda *sides: jnp.stack(sides), *(
            keypoint_model(model, index) for index in (constants.LEFT_HAND21_FROM_SMPLX,
                                                       constants.RIGHT_HAND21_FROM_SMPLX)))
        self.models = jax.device_put(Models(keypoint_model(model, BLAZEPOSE_JOINTS), hands,
                                            openpose_keypoint_model(model)), self.device)
        self.pinhole = (np.float32(lens[0]), np.asarray(lens[1], np.float32))
        self.lens = jax.device_put(self.pinhole, self.device)
        self.num_betas, self.num_expression = model.num_betas, model.num_expression
        self.settings = settings
        self.people: dict[int, tuple[PersonState, float]] = {}  # by identity: state, time last solved

    def warm_up(self) -> None:
        """Compile `step` (on nobody: zeros), so that the first person's frame does not wait for it."""
        shapes = ((33, 4), (2, 21, 3), (2,), (67, 3), (67,), (len(BONES), 3), (len(BONES),))
        obs = jax.device_put(tuple(np.zeros(shape, np.float32) for shape in shapes), self.device)
        jax.block_until_ready(step(self.models, obs, self._fresh(), np.bool_(True), np.float32(1.0), self.lens,
                                   self.num_expression, self.settings))

    def _fresh(self) -> PersonState:
        return jax.device_put(fresh_state(self.num_betas), self.device)

    def __call__(self, people: dict[int, Observations], now: float) -> dict[int, Solved]:
        """Each person of one frame (``Observations`` of one frame) at ``now`` seconds (the frame's time)."""
        solved = {}
        for person_id, obs in people.items():
            directions, weight = bone_directions(obs, self.pinhole)
            arrays = jax.device_put(tuple(np.asarray(a[0], np.float32) for a in (
                obs.body_world, obs.hands_world, obs.hands_conf, obs.keypoints, keypoint_noise_px(obs.keypoints),
                directions, weight)), self.device)
            state, last = self.people.get(person_id, (None, -np.inf))
            fresh = state is None or now - last > self.settings.reset_after
            if fresh:
                new = self._fresh()
                state = new if state is None else new._replace(shape=state.shape, shape_seconds=state.shape_seconds)
            dt = np.float32(max(now - last, 1e-3) if not fresh else 1.0)
            for _ in range(self.settings.warm_up if fresh else 1):
                out, state = step(self.models, arrays, state, np.bool_(fresh), dt, self.lens,
                                  self.num_expression, self.settings)
            solved[person_id] = jax.tree.map(np.asarray, out)
            self.people[person_id] = (state, now)
        return solved
