"""``jaxmocap live --mode hands``: hands alone, frame by frame (`HandSession`, the live session's threads with the
hand tracker). Each tracked hand is solved causally (`hand_step`: IK to its world landmarks warm-started from its
previous frame, a few iterations of the fit to its 2D keypoints, then a few steps of the offline clip fit's
objective, `integrate.hand_clip`, over its last `causal.PAST` frames and this one, as the body's live solve), sent as
a JSON line (`hand_entry`) and recorded as ``hands.npz`` (`HandRecorder`)."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

import smplx_jax
from jaxmocap.compile_cache import disk_jit
from jaxmocap.detect.hand_tracker import Hand, HandTracker
from jaxmocap.hand_motion import hand_meshes
from jaxmocap.integrate.clip import ClipConfig
from jaxmocap.integrate.hand_clip import HAND_CLIP, hand_clip_problem, hand_clip_start, solve_hand_clip
from jaxmocap.integrate.hand_fit import HAND_FIT, HandFit, hand_fit_from, hand_ik_one, hand_keypoint_model, palm_start
from jaxmocap.integrate.inverse_kinematics import IKConfig
from jaxmocap.integrate.keypoints import KeypointModel
from jaxmocap.live.causal import PAST, host
from jaxmocap.live.record import FLUSH_SECONDS, Recording
from jaxmocap.live.session import Session
from jaxmocap.live.source import Frame
from jaxmocap.live.stream import frame_message
from jaxmocap.overlay import Posed
from jaxmocap.pipeline.hands_job import COLUMNS, FIT_COLUMNS, side_arrays
from jaxmocap.pipeline.stages import Lens, lens_of
from jaxmocap.pipeline.whole_clip import hand_bone_directions, part_noise_px
from smplx_jax import SIDES


@dataclass(frozen=True)
class HandSettings:
    """How much each hand's frame solves: ``ik_iterations`` of the IK, ``fit_iterations`` of the fit to its 2D
    keypoints (this frame's start), then the clip fit over the window (``fit``: the offline units, the steps a frame
    affords); a hand unseen for more than ``reset_after`` seconds starts afresh, with ``warm_up`` steps on its first
    frame."""

    ik_iterations: int = 5
    fit_iterations: int = 5
    # two steps of two conjugate-gradient iterations: the window's past frames start where the previous frame's solve
    # left them, and its blocks hold each frame's whole Gauss-Newton matrix; five steps of four took a frame past
    # its 1/60 s on two cores (docs/BENCHMARKS.md, "Hands on their own")
    fit: ClipConfig = dataclasses.replace(HAND_CLIP, iterations=2, cg_iterations=2)
    reset_after: float = 0.5
    warm_up: int = 2


class HandState(NamedTuple):
    """What a hand carries to its next frame: the last IK pose (the next start) and the estimates of the `PAST`
    frames before it (oldest first; ``past_found`` 0 where there was none) with their observations."""

    pose: Float[Array, "55 3"]
    past_pose: Float[Array, "P 16 3"]  # `hand_clip.HandClipUnknowns`' pose and camera
    past_camera: Float[Array, "P 3"]
    past_keypoints: Float[Array, "P 21 3"]
    past_sigma: Float[Array, "P 21"]
    past_directions: Float[Array, "P 20 3"]
    past_direction_weight: Float[Array, "P 20"]
    past_found: Float[Array, "P"]


@disk_jit(static_argnames="settings")
def hand_step(km: KeypointModel, left: Bool[Array, ""], world: Float[Array, "21 3"], keypoints: Float[Array, "21 3"],
              sigma: Float[Array, "21"], directions: Float[Array, "20 3"], direction_weight: Float[Array, "20"],
              state: HandState, fresh: Bool[Array, ""], dt: Float[Array, ""], lens: tuple, settings: HandSettings
              ) -> tuple[HandFit, HandState]:
    """One hand's frame (``left``: its side; ``km`` that side's `hand_keypoint_model`): IK from the closed-form
    start when ``fresh``, else from ``state``'s pose, the fit to its keypoints, then the clip fit of its window
    (``sigma``, ``directions``, ``direction_weight``: `whole_clip.part_noise_px`, `whole_clip.hand_bone_directions`);
    ``dt``: seconds since the hand's last frame (the window's frame rate is ``1 / dt``); ``lens``: (focal length,
    principal point)."""
    ik_config = IKConfig(iterations=settings.ik_iterations)
    start = jnp.where(fresh, palm_start(km, left, world), state.pose)
    pose = hand_ik_one(km, left, world, jnp.ones(21, world.dtype), ik_config, start)
    fitted = hand_fit_from(km, left, keypoints, pose, dataclasses.replace(HAND_FIT,
                                                                          iterations=settings.fit_iterations))
    this = hand_clip_start(fitted.global_orient[None], fitted.hand_pose[None], fitted.camera_scale[None],
                           fitted.camera_trans[None])
    past_found = jnp.where(fresh, 0.0, state.past_found)

    def with_past(past, new):
        return jnp.concatenate([past, new[None]])

    window = this._replace(pose_rotvecs=jnp.concatenate([state.past_pose, this.pose_rotvecs]),
                           transl=jnp.concatenate([state.past_camera, this.transl]))
    data = hand_clip_problem(km, left, with_past(state.past_keypoints, keypoints), window, focal_length=lens[0],
                             principal_point=lens[1], fps=1.0 / dt,
                             keypoint_sigma_px=with_past(state.past_sigma, sigma),
                             directions=with_past(state.past_directions, directions),
                             direction_weight=with_past(state.past_direction_weight, direction_weight),
                             found=jnp.append(past_found > 0, fitted.valid))
    solved = solve_hand_clip(window, data, settings.fit)
    out = HandFit(*(a[-1] for a in (solved.global_orient, solved.hand_pose, solved.camera_scale,
                                    solved.camera_trans)), fitted.valid, solved.reprojection_error_px[-1])
    valid = fitted.valid & jnp.all(jnp.isfinite(jnp.concatenate([out.global_orient, out.hand_pose.ravel(),
                                                                   out.camera_trans])))
    estimates = hand_clip_start(solved.global_orient, solved.hand_pose, solved.camera_scale, solved.camera_trans)

    def shifted(past, new):
        return with_past(past, new)[1:]

    new = HandState(pose, estimates.pose_rotvecs[1:], estimates.transl[1:], shifted(state.past_keypoints, keypoints),
                    shifted(state.past_sigma, sigma), shifted(state.past_directions, directions),
                    shifted(state.past_direction_weight, direction_weight), shifted(past_found, jnp.ones(())))
    new = jax.tree.map(lambda a, b: jnp.where(valid, a, b), new, state)
    return out._replace(valid=valid), new


def fresh_hand_state() -> HandState:
    """The state of a hand not seen before: nothing solved before it."""
    return HandState(jnp.zeros((55, 3)), jnp.zeros((PAST, 16, 3)), jnp.zeros((PAST, 3)), jnp.zeros((PAST, 21, 3)),
                     jnp.ones((PAST, 21)), jnp.zeros((PAST, 20, 3)), jnp.zeros((PAST, 20)), jnp.zeros(PAST))


class HandSolver:
    """Each hand's `hand_step`, frame after frame, through the pinhole ``lens``, with its state kept by
    ``hand_id``."""

    def __init__(self, model: smplx_jax.BodyModel, lens: Lens, settings: HandSettings = HandSettings()):
        self.device = host()  # as the body's live solve (`jaxmocap.live.causal.host`)
        self.models = jax.device_put({side: hand_keypoint_model(model, side) for side in SIDES}, self.device)
        self.pinhole = (np.float32(lens[0]), np.asarray(lens[1], np.float32))
        self.lens = jax.device_put(self.pinhole, self.device)
        self.settings = settings
        self.hands: dict[int, tuple[HandState, float]] = {}

    def warm_up(self) -> None:
        """Compile `hand_step` (on no hand: zeros) before the first frame."""
        self._step("left", np.zeros((21, 3)), np.zeros((21, 3)), self._fresh(), True, 1.0)

    def _fresh(self) -> HandState:
        return jax.device_put(fresh_hand_state(), self.device)

    def _step(self, side, world, keypoints, state, fresh, dt):
        world, keypoints = (np.asarray(a, np.float32) for a in (world, keypoints))
        sigma = np.repeat(part_noise_px(keypoints[None]), 21).astype(np.float32)
        directions, weight = (np.asarray(a[0], np.float32) for a in hand_bone_directions(
            keypoints[None], world[None], keypoints[None, 0, 2], self.pinhole))
        arrays = jax.device_put((world, keypoints, sigma, directions, weight), self.device)
        return jax.block_until_ready(hand_step(self.models[side], np.bool_(side == "left"), *arrays, state,
                                               np.bool_(fresh), np.float32(dt), self.lens, self.settings))

    def __call__(self, hands: list[Hand], now: float) -> dict[int, HandFit]:
        """Each hand of one frame at ``now`` seconds (the frame's time), by ``hand_id``."""
        solved = {}
        for hand in hands:
            state, last = self.hands.get(hand.hand_id, (None, -np.inf))
            fresh = state is None or now - last > self.settings.reset_after
            state = self._fresh() if fresh else state
            dt = max(now - last, 1e-3) if not fresh else 1.0
            for _ in range(self.settings.warm_up if fresh else 1):
                out, state = self._step(hand.side, hand.world, hand.keypoints_2d, state, fresh, dt)
            solved[hand.hand_id] = jax.tree.map(np.asarray, out)
            self.hands[hand.hand_id] = (state, now)
        return solved


def hand_entry(hand: Hand, fit: HandFit) -> dict:
    """One hand's entry of a frame message: identity, side, the hands.npz keys of the hand, and its keypoints."""
    return {"id": int(hand.hand_id), "side": hand.side,
            "global_orient": np.round(np.asarray(fit.global_orient, np.float64), 5).tolist(),
            "hand_pose": np.round(np.asarray(fit.hand_pose, np.float64), 5).tolist(),
            "camera_scale": round(float(fit.camera_scale), 4),
            "camera_trans": np.round(np.asarray(fit.camera_trans, np.float64), 3).tolist(),
            "keypoints_2d": np.round(hand.keypoints_2d, 2).tolist()}


class HandRecorder(Recording):
    """A hands session's frames (`add`: the source frame's number and time, its hands and their fits by
    ``hand_id``) as ``hands.npz``, each frame's likeliest hand of each side."""

    bools = tuple(f"{side}_valid" for side in SIDES)
    nothing = ([], {})

    def __init__(self, folder, model_sha256: str, fps: float, image_size: tuple[int, int],
                 every_s: float = FLUSH_SECONDS):
        super().__init__(folder, {"fps": np.asarray(fps), "image_size": np.asarray(image_size),
                                  "model_sha256": np.asarray(model_sha256)}, every_s)

    def _rows(self, frames, names):
        rows = [{"frame": t, "hand_id": hand.hand_id, "side": SIDES.index(hand.side),
                 "keypoints_2d": hand.keypoints_2d, "world": hand.world, "score": hand.score, "box": hand.box}
                | {k: getattr(solved[hand.hand_id], k) for k in FIT_COLUMNS}
                for t, (hands, solved) in enumerate(frames) for hand in hands]
        table = {k: np.asarray([r[k] for r in rows]).reshape((len(rows),) + shape) for k, shape in COLUMNS.items()}
        return {"hands": side_arrays(table, len(frames))}  # as solved live, each frame causal

    def _write(self):
        return [self._npz(self.folder / "hands.npz", "hands")]


class HandSession(Session):
    """`Session` of ``--mode hands``: the hand tracker (up to ``max_hands``), `HandSolver`, `HandRecorder`; the
    frame message lists ``"hands"`` (`hand_entry`); the page draws the hand meshes."""

    noun = "hands"

    def _setup(self, model_sha256: str) -> None:
        config = self.config
        self.lens = (None, None)  # each hand has its weak-perspective camera
        self.hand_models = {side: smplx_jax.hand_model(self.model, side) for side in SIDES}
        self.solver = HandSolver(self.model, lens_of(self.source.size, config.focal_length))
        self.detector = HandTracker(static_image_mode=False, max_hands=config.max_hands)
        self.recorder = None if config.record is None else HandRecorder(config.record, model_sha256,
                                                                         self.source.fps, self.source.size)

    def warm_up(self) -> None:
        self.solver.warm_up()
        if self.viewer is not None:
            zeros = np.zeros((1, 3), np.float32)
            for side in SIDES:
                hand_meshes(self.hand_models[side], zeros, np.zeros((1, 15, 3), np.float32))

    def _observe(self, image: np.ndarray) -> list[Hand]:
        return self.detector(image)

    def _solve(self, frame: Frame, hands: list[Hand]) -> dict[int, tuple[Hand, HandFit]]:
        now = frame.arrived if self.source.live else frame.index / self.source.fps
        with self._stage("fit"):
            fits = self.solver(hands, now)
        with self._stage("output"):
            if self.sender is not None:
                entries = [hand_entry(h, fits[h.hand_id]) for h in hands if fits[h.hand_id].valid]
                self.sender.send(frame_message(frame.index, now, [], hands=entries))
            if self.recorder is not None:
                self.recorder.add(frame.index, now, hands, fits)
        return {h.hand_id: (h, fits[h.hand_id]) for h in hands}

    def _posed(self, solved: dict[int, tuple[Hand, HandFit]]) -> list[Posed]:
        posed = []
        for hand, fit in solved.values():
            if fit.valid:
                mesh = hand_meshes(self.hand_models[hand.side], fit.global_orient[None], fit.hand_pose[None])
                posed.append(Posed(SIDES.index(hand.side), np.asarray(mesh.vertices[0]), float(fit.camera_scale),
                                   fit.camera_trans, np.asarray(self.hand_models[hand.side].faces),
                                   hand.side[0].upper()))
        return posed
