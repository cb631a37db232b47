"""Each person's motion over the whole run as one fit (`jaxmocap.integrate.fit_clip`), in windows placed by frame
number: what the fit observes of a track (each keypoint's detector noise, the bones' directions from the 3D
landmarks in the camera's axes, a hand lost for a moment interpolated), one shape for the person from frames
spread over the run, each limb's depth in the start chosen over the whole run (`integrate.clip_start`: its costs
window by window, the choice over all frames), then the poses and translations window by window with that shape
held. A window's result depends only on the frames it covers, so the motion is the same whatever chunks the run was
stored in, in time linear in the run's length and memory flat (but for the choice's costs, about 2 kB a frame).
On a known floor (`ClipGround`, from the fitted motion: `jaxmocap.integrate.ground.standing`) a fit is solved again,
window by window from its own poses, with its feet planted where they carry weight.
"""

import dataclasses
import functools
from collections.abc import Callable
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Bool, Float
from scipy.spatial.transform import Rotation

import smplx_jax
from jaxmocap.compile_cache import disk_jit
from jaxmocap.integrate import ClipConfig, ClipGround, fit_clip
from jaxmocap.integrate.camera import weak_perspective_least_squares
from jaxmocap.integrate.clip import (
    BLAZEPOSE_OF_BODY25,
    BODY_BONES,
    BONES,
    HAND_BONES,
    SOLVED_JOINTS,
    clip_problem,
    points_3d,
)
from jaxmocap.integrate.clip_start import hypothesis_costs, limb_codes, with_codes
from jaxmocap.integrate.fitting import openpose_keypoint_model
from jaxmocap.pipeline.observe import HAND_GAP_SECONDS, Observations, fill_hand_gaps
from jaxmocap.pipeline.stages import initial_bodies
from jaxmocap.pipeline.tracks import Bodies, Track

# The landmark models' 2D noise, a share of the extent of what they crop: a few pixels of their 256- or 224-pixel
# inputs, whose crops span 1.25-2 times the person or the hand; and never below one pixel of the image, whose
# sampling (and compression) no detector sees through.
NOISE = 0.01
NOISE_FLOOR_PX = 1.0
# Windows: each keeps WINDOW frames and is fitted with MARGIN more on each side, left out of its result. The motion
# term ties a frame to the next ones over about sqrt(keypoint noise / (acceleration sigma * frame time^2)) frames
# (a couple at 30-60 frames/s), so a window's frames near its edges see what they would in one fit of the clip.
WINDOW = 64
MARGIN = 8
# The shape's ten numbers are fitted on this many frames spread over the track (each gives over a hundred keypoint
# coordinates and their bones' directions), then held in every window. In a video they are SHAPE_RUNS runs of
# consecutive frames, each fitted with its motion (without it, a frame seen in 2D alone has directions, depth and
# twists, that only the priors hold, and the solve crawls along them), a frame left out after each run so that no
# acceleration joins two runs.
SHAPE_FRAMES = 32
SHAPE_RUNS = 4
# Windows solved together on an accelerator (`windows_at_once`).
ACCELERATOR_WINDOWS = 16
HAND_SLICES = (slice(25, 46), slice(46, 67))


def part_noise_px(part: Float[ArrayLike, "T N 3"]) -> np.ndarray:
    """``(T,)`` the detector noise in pixels of each frame's keypoints of one part (a body, a hand): `NOISE`
    times the larger side of the box of those seen, at least `NOISE_FLOOR_PX`."""
    part = np.asarray(part, np.float64)
    seen = part[..., 2] > 0
    low = np.where(seen[..., None], part[..., :2], np.inf).min(1)
    high = np.where(seen[..., None], part[..., :2], -np.inf).max(1)
    side = np.max(high - low, -1)
    return np.maximum(NOISE * np.where(np.isfinite(side) & (side > 0), side, 1.0), NOISE_FLOOR_PX)


def keypoint_noise_px(keypoints: np.ndarray) -> np.ndarray:
    """``(T, 67)`` each keypoint's detector noise in pixels: its body's (BODY_25) or its hand's `part_noise_px`."""
    keypoints = np.asarray(keypoints, np.float64)
    sigma = np.empty(keypoints.shape[:2])
    for part in (slice(0, 25), *HAND_SLICES):
        sigma[:, part] = part_noise_px(keypoints[:, part])[:, None]
    return sigma.astype(np.float32)


def _ray_rotations(pixels: np.ndarray, lens) -> np.ndarray:
    """``(T, 3, 3)``: the rotations taking the camera's axis onto the ray through each pixel ``(T, 2)``. A landmark
    model sees its crop from the ray through the crop, not along the camera's axis: its 3D landmarks are turned by
    this into the camera's axes."""
    focal, centre = lens
    ray = np.concatenate([(pixels - centre) / focal, np.ones((len(pixels), 1))], 1)
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    axis = np.cross([0.0, 0.0, 1.0], ray)
    sine = np.linalg.norm(axis, axis=1, keepdims=True)
    rotvec = np.where(sine > 0, axis / np.maximum(sine, 1e-12), 0.0) * np.arctan2(sine, ray[:, 2:])
    return Rotation.from_rotvec(rotvec).as_matrix()


def _unit(vectors, weight):
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    ok = length[..., 0] > 1e-6
    return np.where(ok[..., None], vectors / np.maximum(length, 1e-6), 0.0), np.where(ok, weight, 0.0)


def bone_directions(obs: Observations, lens) -> tuple[np.ndarray, np.ndarray]:
    """The directions of `clip.BONES` ``(T, N, 3)`` that the 3D landmarks of ``obs`` give, in the camera's axes
    (each set turned by `_ray_rotations` at its body's or hand's pixel), and their confidence ``(T, N)``: a body
    bone's the lower visibility of its ends, a hand bone's the hand's presence; 0 where not seen."""
    keypoints = np.asarray(obs.keypoints, np.float64)
    seen = keypoints[:, :25, 2] > 0
    centre = np.where(keypoints[:, 8:9, 2] > 0, keypoints[:, 8, :2],
                      np.sum(np.where(seen[..., None], keypoints[:, :25, :2], 0.0), 1)
                      / np.maximum(seen.sum(1), 1)[:, None])
    turn = _ray_rotations(centre, lens)
    world = np.asarray(obs.body_world, np.float64)
    a, b = (np.asarray([BLAZEPOSE_OF_BODY25[k] for k in side]) for side in zip(*BODY_BONES))
    body, body_weight = _unit(np.einsum("tij,tnj->tni", turn, world[:, b, :3] - world[:, a, :3]),
                              np.minimum(world[:, a, 3], world[:, b, 3]))
    parts, weights = [body], [body_weight]
    for side, part in enumerate(HAND_SLICES):
        unit, weight = hand_bone_directions(keypoints[:, part], obs.hands_world[:, side], obs.hands_conf[:, side],
                                            lens, turn)
        parts.append(unit)
        weights.append(weight)
    found = np.asarray(obs.found)[:, None]
    return (np.concatenate(parts, 1).astype(np.float32),
            np.where(found, np.concatenate(weights, 1), 0.0).astype(np.float32))


def hand_bone_directions(keypoints: Float[ArrayLike, "T 21 3"], world: Float[ArrayLike, "T 21 3"],
                         presence: Float[ArrayLike, "T"], lens, turn=None) -> tuple[np.ndarray, np.ndarray]:
    """The directions of `clip.HAND_BONES` ``(T, 20, 3)`` that a hand's 3D landmarks ``world`` give, turned into
    the camera's axes by `_ray_rotations` at its wrist's pixel (where its keypoints are missing, by ``turn (T, 3,
    3)``, default none), and their confidence ``(T, 20)``, the hand's ``presence``; 0 where not seen."""
    keypoints = np.asarray(keypoints, np.float64)
    wrist = keypoints[:, 0]
    turn = np.broadcast_to(np.eye(3), (len(wrist), 3, 3)) if turn is None else turn
    hand_turn = np.where((wrist[:, 2] > 0)[:, None, None], _ray_rotations(wrist[:, :2], lens), turn)
    hand = np.asarray(world, np.float64)
    a, b = (np.asarray(ends) for ends in zip(*HAND_BONES))
    return _unit(np.einsum("tij,tnj->tni", hand_turn, hand[:, b] - hand[:, a]),
                 np.broadcast_to(np.asarray(presence, np.float64)[:, None], (len(hand), len(a))))


def window_spans(count: int):
    """Each window over ``count`` frames: its frames (`WINDOW` and `MARGIN` on each side, placed by frame number,
    padded at the ends with repeats), which of them lie in the track, and which it keeps (its own `WINDOW`)."""
    for first in range(0, count, WINDOW):
        span = np.arange(first - MARGIN, first + WINDOW + MARGIN)
        inside = (span >= 0) & (span < count)
        yield np.clip(span, 0, count - 1), inside, inside & (span >= first) & (span < first + WINDOW)


def _windows_of(fun):
    """``fun`` over windows, their arrays (but for the lens and frame rate) leading with a window axis; matrix
    products in full float32 on every device, as the clip fit's."""
    def over_windows(model, keypoints, start, focal_length, principal_point, fps, sigma, directions, weight, found,
                     ground, turns, *, fit_betas: bool, config: ClipConfig):
        def one(k, s, g, d, w, f, floor, turn):
            return fun(model, k, s, focal_length, principal_point, fps, g, d, w, f, floor, turn, fit_betas=fit_betas,
                       config=config)

        windows = (keypoints, start, sigma, directions, weight, found, ground, turns)
        with jax.default_matmul_precision("highest"):
            if keypoints.shape[0] == 1:  # unbatched: a vmapped solve's loop selects every value it carries each step
                return jax.tree.map(lambda a: a[None], one(*jax.tree.map(lambda a: a[0], windows)))
            return jax.vmap(one)(*windows)

    return disk_jit(functools.wraps(fun)(over_windows), static_argnames=("fit_betas", "config"))


@_windows_of
def _fit(model, keypoints, start, focal_length, principal_point, fps, sigma, directions, weight, found, ground,
         turns, *, fit_betas: bool, config: ClipConfig):
    return fit_clip(model, keypoints, start, focal_length=focal_length, principal_point=principal_point, fps=fps,
                    keypoint_sigma_px=sigma, directions=directions, direction_weight=weight, found=found,
                    fit_betas=fit_betas, ground=ground, scene_from_camera=turns, config=config)


@_windows_of
def _hypotheses(model, keypoints, start, focal_length, principal_point, fps, sigma, directions, weight, found,
                ground, turns, *, fit_betas: bool, config: ClipConfig):
    y, data = clip_problem(model, keypoints, start, focal_length=focal_length, principal_point=principal_point,
                           fps=fps, keypoint_sigma_px=sigma, directions=directions, direction_weight=weight,
                           found=found, fit_betas=fit_betas, scene_from_camera=turns)
    return hypothesis_costs(y, data, config)


_limb_codes = jax.jit(limb_codes)


def weak_camera(km, params: smplx_jax.SMPLXParams, focal_length, principal_point, confidence: Float[ArrayLike, "67"]):
    """The weak-perspective camera (scale, translation) closest to the pinhole's projection of one frame's
    keypoints, those with ``confidence`` > 0 weighing ten times the others."""
    x = points_3d(km, params.full_pose(), params.betas, params.transl)
    pixels = focal_length * x[:, :2] / x[:, 2:] + principal_point
    return weak_perspective_least_squares(x[:, :2], pixels, jnp.where(confidence > 0, 1.0, 0.1))


_weak_cameras = jax.jit(jax.vmap(weak_camera, in_axes=(None, 0, None, None, 0)))


def _observations(track: Track) -> Observations:
    return Observations(track.keypoints_2d, track.body_world, track.hands_world, track.hands_conf, track.body_box,
                        track.hand_boxes, track.found)


def blocks(count: int):
    """Each block of `WINDOW` frames of ``count``, placed by frame number: its frames (the last block padded with
    the last frame, so that one program serves every block) and how many of them are its own."""
    for first in range(0, count, WINDOW):
        yield np.minimum(np.arange(first, first + WINDOW), count - 1), min(WINDOW, count - first)


def windows_at_once() -> int:
    """Windows solved together, as one batched program: one on a CPU, where a batch costs the sum of its windows'
    arithmetic and waits for its slowest; `ACCELERATOR_WINDOWS` on an accelerator, where a step's time is set by
    its launches, not its arithmetic, so that a batch of windows takes about one window's time."""
    return 1 if jax.default_backend() == "cpu" else ACCELERATOR_WINDOWS


def with_start(model: smplx_jax.BodyModel, track: Track, lens) -> Track:
    """The track with each frame's start for the clip fit (`stages.initial_bodies`: IK from its 3D landmarks,
    placed in the pinhole ``lens``), solved in windows of `WINDOW` frames placed by frame number (the last padded
    with its last frame): a batched solve's rounding depends on what shares its batch, and the clip fit's flat
    directions (depth, twists) carry such differences far, so the start must not depend on the chunks the run was
    observed in."""
    parts = []
    for frames, kept in blocks(len(track.found)):
        window = _observations(jax.tree.map(lambda a: np.asarray(a)[frames], track))
        if not window.found.any():  # (a person of a long run absent for a while)
            parts.append(Bodies.absent(kept, model))
            continue
        parts.append(jax.tree.map(lambda a: np.asarray(a)[:kept], initial_bodies(model, window, lens)))
    return dataclasses.replace(track, bodies=Bodies.concatenate(parts))


def with_hand_gaps_filled(track: Track, max_gap: int) -> Track:
    """The track with each hand lost for at most ``max_gap`` frames interpolated (`observe.fill_hand_gaps`), over
    the whole track: the same whatever chunks it was observed in."""
    filled = fill_hand_gaps(_observations(track), max_gap)
    return dataclasses.replace(track, keypoints_2d=filled.keypoints, hands_world=filled.hands_world,
                               hands_conf=filled.hands_conf, hand_boxes=filled.hand_boxes)


def shape_frames(valid: Bool[ArrayLike, "T"], video: bool) -> tuple[np.ndarray, np.ndarray]:
    """The `SHAPE_FRAMES` frames the shape is fitted on and which of them count: of a ``video``, `SHAPE_RUNS`
    runs of consecutive frames starting at valid frames spread over the track, each followed by one left out (the
    runs' valid frames count); else valid frames spread over the track (padded with the last, not counting)."""
    seen = np.flatnonzero(valid)
    if video:
        run = SHAPE_FRAMES // SHAPE_RUNS
        starts = seen[np.round(np.linspace(0, len(seen) - 1, SHAPE_RUNS)).astype(int)]
        starts = np.minimum(starts, max(len(valid) - run, 0))
        frames = np.minimum((starts[:, None] + np.arange(run)).ravel(), len(valid) - 1)
        found = np.asarray(valid)[frames] & np.tile(np.arange(run) < run - 1, SHAPE_RUNS)
        return frames, found
    spread = seen[np.unique(np.round(np.linspace(0, len(seen) - 1, min(len(seen), SHAPE_FRAMES))).astype(int))]
    return np.concatenate([spread, np.full(SHAPE_FRAMES - len(spread), spread[-1])]), np.arange(SHAPE_FRAMES) < len(
        spread)


class FittedClip(NamedTuple):
    """`fitted_clip`'s bodies, and for each frame whether the fits it came from (the shape's, its window's) met
    their stopping rule rather than their step cap."""

    bodies: Bodies
    converged: np.ndarray  # (T,) bool


def fitted_track(model: smplx_jax.BodyModel, track: Track, lens, fps: float | None,
                 config: ClipConfig = ClipConfig(), ground: ClipGround | None = None,
                 scene_from_camera: Float[ArrayLike, "T 3"] | None = None) -> Bodies:
    """The track's bodies as one fit (`fitted_clip`) through the pinhole ``lens``, observing its 2D keypoints and
    its 3D landmarks' bone directions (`bone_directions`), a hand lost for a moment interpolated in a video:
    ``track.bodies`` is each frame's start (its ``transl`` in the camera frame); ``fps`` the frame rate (None:
    unrelated images, no motion between them). With ``ground`` (its floor and the feet's contacts,
    `integrate.ground.Standing.clip_ground`), ``track.bodies`` is a fit of the track already, refitted standing
    on it. ``scene_from_camera``: each frame's camera turned into the scene's axes (None: a static camera). Valid
    where the start was."""
    if fps:
        track = with_hand_gaps_filled(track, round(HAND_GAP_SECONDS * fps))
    directions, weight = bone_directions(_observations(track), lens)
    return fitted_clip(model, track.keypoints_2d, track.bodies.params, track.found & track.bodies.valid, lens, fps,
                       directions, weight, config, ground=ground, scene_from_camera=scene_from_camera).bodies


def fitted_clip(model: smplx_jax.BodyModel, keypoints_2d: Float[ArrayLike, "T 67 3"], start: smplx_jax.SMPLXParams,
                valid: Bool[ArrayLike, "T"], lens, fps: float | None,
                directions: Float[ArrayLike, "T N 3"] | None = None,
                direction_weight: Float[ArrayLike, "T N"] | None = None, config: ClipConfig = ClipConfig(),
                progress: Callable[[int], object] | None = None, ground: ClipGround | None = None,
                scene_from_camera: Float[ArrayLike, "T 3"] | None = None) -> FittedClip:
    """One person's frames as one fit (module docstring) through the pinhole ``lens``: ``keypoints_2d`` the 2D
    targets, ``start`` each frame's start (T leading, ``transl`` in the camera frame), fitted where ``valid``;
    ``directions`` and ``direction_weight`` the bones' observed directions and their confidence (None: none
    observed, the 2D keypoints alone); ``fps`` the frame rate (None: unrelated images, no motion between them).
    ``ground`` (`ClipGround`, ``contact (T, 4)``): the floor the person stands on and where their feet carry
    weight; ``start`` is then a fit already (its shape held, its poses the start as they are) refitted on it.
    ``progress(frames)`` is told of each window's frames as they are fitted. Valid where ``valid`` and finite."""
    valid = np.asarray(valid, bool)
    count = len(valid)
    if not valid.any():
        return FittedClip(Bodies(start, np.ones(count, np.float32), np.zeros((count, 2), np.float32), valid), valid)
    keypoints = np.asarray(keypoints_2d, np.float32)
    sigma = keypoint_noise_px(keypoints)
    if directions is None:
        directions = np.zeros((count, len(BONES), 3), np.float32)
        direction_weight = np.zeros((count, len(BONES)), np.float32)
    directions, weight = np.asarray(directions, np.float32), np.asarray(direction_weight, np.float32)
    focal, centre = np.float32(lens[0]), np.asarray(lens[1], np.float32)
    on = jax.tree.map(lambda a: np.asarray(a, np.float32), ClipGround.none(count) if ground is None else ground)
    turns = np.zeros((count, 3), np.float32) if scene_from_camera is None else np.asarray(scene_from_camera,
                                                                                          np.float32)

    def solve(fit, frames, found, rate, betas=None):
        """Windows of frames ``frames`` ``(W, F)`` (indices, padded with repeats), each as one clip, the shape
        ``betas`` held (None: fitted): ``fit`` is `_fit` or `_hypotheses`."""
        pick = jax.tree.map(lambda a: np.asarray(a)[frames], start)
        if betas is not None:
            pick = pick.replace(betas=np.broadcast_to(betas, pick.betas.shape).astype(np.float32))
        windows = len(frames)
        under = ClipGround(*(np.broadcast_to(a, (windows, *a.shape)) for a in (on.floor, on.above_sole)),
                           on.contact[frames], np.broadcast_to(on.known, (windows,)))
        return jax.device_get(fit(model, keypoints[frames], pick, focal, centre, np.float32(rate), sigma[frames],
                                  directions[frames], weight[frames], found, under, turns[frames],
                                  fit_betas=betas is None, config=config))

    def in_windows(fit, betas, keep=lambda result, frames: result, told=lambda frames: None):
        """What ``keep`` takes of ``fit``'s results and the window's frames (frames leading) over the track, window
        by window (`windows_at_once` of them solved together, placed by frame number; the last group padded with
        its last window), each window's frames ``told``."""
        spans, parts, at_once = list(window_spans(count)), [], windows_at_once()
        for first in range(0, len(spans), at_once):
            group = spans[first:first + at_once]
            frames, inside, core = (np.stack(a) for a in zip(*group + group[-1:] * (at_once - len(group))))
            results = solve(fit, frames, inside & valid[frames], fps or 0.0, betas)
            for w in range(len(group)):
                result = keep(jax.tree.map(lambda a: a[w], results), frames[w])
                parts.append(jax.tree.map(lambda a: np.asarray(a)[core[w]], result))
                told(int(core[w].sum()))
        return jax.tree.map(lambda *a: np.concatenate(a), *parts)

    if ground is not None:  # refitted on the floor from a fit: its shape, its poses
        shape, shaped_converged = np.asarray(start.betas[np.argmax(valid)]), True
    else:  # one shape, fitted on `shape_frames`
        frames, found = shape_frames(valid, bool(fps))
        shaped = solve(_fit, frames[None], found[None], fps or 0.0)
        shape, shaped_converged = np.asarray(shaped.params.betas[0, 0]), bool(shaped.converged[0])
    if fps and ground is None:  # each limb's depth chosen over the whole track (`clip_start`)
        unary, triple, hypotheses = in_windows(_hypotheses, shape)
        codes = _limb_codes(unary, triple)
        pose = np.asarray(jax.vmap(smplx_jax.SMPLXParams.full_pose)(start))[:, list(SOLVED_JOINTS)]
        start = start.replace(body_pose=np.asarray(with_codes(pose, hypotheses, codes))[:, 1:22])

    def with_cameras(result, frames):  # and whether the window converged
        cameras = _weak_cameras(openpose_keypoint_model(model), result.params, focal, centre,
                                keypoints[frames][..., 2])
        return result.params, cameras, jnp.full(frames.shape, result.converged)

    params, (scale, trans), converged = in_windows(_fit, shape, with_cameras, progress or (lambda frames: None))
    finite = np.all(np.isfinite(np.asarray(jax.vmap(smplx_jax.SMPLXParams.full_pose)(params))), (1, 2))
    return FittedClip(Bodies(params, scale, trans, valid & finite), converged & shaped_converged)
