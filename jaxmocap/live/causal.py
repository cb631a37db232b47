"""The live path's solve of each person in each frame, causal: IK warm-started from the person's previous frame
(its priors on the rest pose, as offline: a warm start is where the solve begins, not where it is held), a few
iterations of the fit to the 2D keypoints, then the One-Euro filter; one compiled call per person and frame
(`step`), on the host's CPU (`host`)."""

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

import smplx_jax
from jaxmocap.compile_cache import disk_jit
from jaxmocap.integrate.fitting import OK, default_pose, fit_one, lens_arrays, openpose_keypoint_model
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
from jaxmocap.live.one_euro import Filtered, OneEuro, one_euro, one_euro_rotvecs, quaternion_state, start_state
from jaxmocap.pipeline.observe import Observations
from jaxmocap.pipeline.stages import FIT_FROM_IK, Lens
from smplx_jax import constants


@dataclass(frozen=True)
class LiveSettings:
    """How much each frame solves, and how the One-Euro filter smooths: rotations (speeds in quaternion units
    per second, about half the angular speed in radians), the translation across the image and in depth (metres;
    depth, which one view barely sees, the most) and the weak-perspective camera (pixels). Lighter filters lag
    less and jitter more (docs/BENCHMARKS.md, "Live"). The shape is the mean of the fitted shapes over the
    person's first ``shape_settle`` seconds, then held: the fit keeps it and moves only pose and camera. A person
    unseen for more than ``reset_after`` seconds starts afresh (their shape kept), with ``warm_up`` steps on
    their first frame. ``hands``: the hands' IK runs (not with ``--mode body``: the hands stay flat)."""

    hands: bool = True
    ik_iterations: int = 5
    fit_iterations: int = 5
    rotations: OneEuro = OneEuro(min_cutoff=1.0, beta=10.0)
    translation: OneEuro = OneEuro(min_cutoff=1.0, beta=20.0)
    depth: OneEuro = OneEuro(min_cutoff=0.3, beta=2.0)
    camera: OneEuro = OneEuro(min_cutoff=1.0, beta=0.5)
    shape_settle: float = 1.0
    reset_after: float = 0.5
    warm_up: int = 4


class PersonState(NamedTuple):
    """What a person carries to their next frame: the last IK pose and shape (the next start), the filters and
    their shape (the mean over ``shape_seconds`` of frames)."""

    theta: Float[Array, "55 3"]
    betas: Float[Array, "B"]
    rotations: Filtered  # (55, 4) quaternions of the full pose
    translation: Filtered  # (1, 2): across the image
    depth: Filtered  # (1, 1)
    camera: Filtered  # (1, 3): scale, tx, ty
    shape: Float[Array, "B"]
    shape_seconds: Float[Array, ""]


class Solved(NamedTuple):
    """One person's body in one frame, filtered; ``valid``: the fit succeeded."""

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
    """The state of a person not seen before: the fit's default pose, mean shape (filters reset on use), no
    shape yet."""
    theta = default_pose()
    betas = jnp.zeros(num_betas, jnp.float32)
    return PersonState(theta, betas, quaternion_state(theta), start_state(jnp.zeros((1, 2))),
                       start_state(jnp.zeros((1, 1))), start_state(jnp.zeros((1, 3))), betas, jnp.zeros(()))


def host() -> jax.Device:
    """Where the live path solves: the host's CPU, also beside a GPU. One frame's solve is a few hundred small
    operations in short loops, bound by each operation's launch, not its work: on an H200 machine a frame took
    36 ms on the GPU and 12 ms on its CPU (docs/BENCHMARKS.md, "Live")."""
    return jax.devices("cpu")[0]


_BODY_MASK = jnp.asarray(BODY_IK_JOINTS, jnp.float32)
_HAND_MASKS = jnp.asarray([LEFT_HAND_IK_JOINTS, RIGHT_HAND_IK_JOINTS], jnp.float32)  # (2, 55)


@disk_jit(static_argnames=("num_expression", "settings"))
def step(models: Models, obs: tuple, state: PersonState, fresh: Bool[Array, ""], dt: Float[Array, ""], lens: tuple,
         num_expression: int, settings: LiveSettings) -> tuple[Solved, PersonState]:
    """One person's frame: ``obs`` = (BlazePose world landmarks (33, 4), hand world landmarks (2, 21, 3), hand
    presence (2,), OpenPose keypoints (67, 3)); ``fresh``: the filters start here; ``dt``: seconds since the
    person's last frame; ``lens``: `lens_arrays`."""
    world, hands_world, hands_conf, keypoints = obs
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
    fit_config = dataclasses.replace(FIT_FROM_IK, iterations=settings.fit_iterations)
    settled = state.shape_seconds >= settings.shape_settle
    fitted = fit_one(models.openpose, keypoints, theta, jnp.where(settled, state.shape, betas), None, lens,
                     fit_config, fit_betas=jnp.where(settled, 0.0, 1.0), differentiable=False)
    p = fitted.params
    camera = jnp.concatenate([fitted.camera_scale[None], fitted.camera_trans])[None]
    weight = jnp.where(fresh | settled, 0.0, jnp.minimum(dt, 0.1))  # seconds this frame adds to the shape's mean
    seconds = state.shape_seconds + weight
    shape = jnp.where(state.shape_seconds > 0, (state.shape * state.shape_seconds + p.betas * weight)
                      / jnp.maximum(seconds, 1e-6), p.betas)
    shape = jnp.where(settled, state.shape, shape)
    begin = jax.tree.map(lambda a, b: jnp.where(fresh, a, b), PersonState(
        theta, betas, quaternion_state(p.full_pose()), start_state(p.transl[None, :2]),
        start_state(p.transl[None, 2:]), start_state(camera), state.shape, state.shape_seconds), state)
    pose, rotations = one_euro_rotvecs(p.full_pose(), begin.rotations, dt, settings.rotations)
    across, translation = one_euro(p.transl[None, :2], begin.translation, dt, settings.translation)
    depth, depth_state = one_euro(p.transl[None, 2:], begin.depth, dt, settings.depth)
    cam, camera = one_euro(camera, begin.camera, dt, settings.camera)
    valid = fitted.status == OK
    new = PersonState(theta, betas, rotations, translation, depth_state, camera, shape, seconds)
    new = jax.tree.map(lambda a, b: jnp.where(valid, a, b), new, state)
    params = params_of(pose, shape, num_expression).replace(transl=jnp.concatenate([across[0], depth[0]]))
    return Solved(params, cam[0, 0], cam[0, 1:], valid), new


class CausalSolver:
    """Each person's `step`, frame after frame, with their state kept by identity."""

    def __init__(self, model: smplx_jax.BodyModel, lens: Lens, settings: LiveSettings = LiveSettings()):
        self.device = host()
        hands = jax.tree.map(lambda *sides: jnp.stack(sides), *(
            keypoint_model(model, index) for index in (constants.LEFT_HAND21_FROM_SMPLX,
                                                       constants.RIGHT_HAND21_FROM_SMPLX)))
        self.models = jax.device_put(Models(keypoint_model(model, BLAZEPOSE_JOINTS), hands,
                                            openpose_keypoint_model(model)), self.device)
        self.lens = jax.device_put(lens_arrays(lens[0], lens[1], jnp.float32), self.device)
        self.num_betas, self.num_expression = model.num_betas, model.num_expression
        self.settings = settings
        self.people: dict[int, tuple[PersonState, float]] = {}  # by identity: state, time last solved

    def warm_up(self) -> None:
        """Compile `step` (on nobody: zeros), so that the first person's frame does not wait for it."""
        obs = jax.device_put(tuple(np.zeros(shape, np.float32) for shape in ((33, 4), (2, 21, 3), (2,), (67, 3))),
                             self.device)
        jax.block_until_ready(step(self.models, obs, self._fresh(), np.bool_(True), np.float32(1.0), self.lens,
                                   self.num_expression, self.settings))

    def _fresh(self) -> PersonState:
        return jax.device_put(fresh_state(self.num_betas), self.device)

    def __call__(self, people: dict[int, Observations], now: float) -> dict[int, Solved]:
        """Each person of one frame (``Observations`` of one frame) at ``now`` seconds (the frame's time)."""
        solved = {}
        for person_id, obs in people.items():
            arrays = jax.device_put(tuple(np.asarray(a[0], np.float32) for a in (
                obs.body_world, obs.hands_world, obs.hands_conf, obs.keypoints)), self.device)
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
