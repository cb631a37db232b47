"""One facing through time. A monocular fit resolves the depth of the torso and limbs from one frame's 2D
keypoints: one frame may turn a limb (or the whole body) towards the camera and the next away, each matching its
image. Here the valid frames are split where a body joint turns by more than `TURN_DEG` between consecutive frames;
from the longest run of frames without such a turn outwards, a frame across one is fitted again from its
neighbour's rotations of the joints that turned (`_start`), the person's shape held, and takes that fit where it
reprojects no farther from the keypoints than the frame's own (within `TIE_PX`, a tie in float32): the ambiguity
resolved as in the frames beside it. A turn the image demands (the refit reprojects farther) stays. (Letting
refits reproject 10% or 1 px farther took cam01 from 61.0 to 63.8-65.2 mm PA-MPJPE: poses the image does not
support. A tie of the standard error of the frame's mean distance, or half of it, took the two-person take's woman
at 30 frames/s from 1.3% of joint-frames turning > 45 degrees to 0.4 or 0.7%, and cam01 mirrored from 61.6 to
63.6 mm either way.) A turn of the wrists alone is the hand's own ambiguity, its fingers bent to match either
turn: refitted with that hand's fingers free, it is taken within `WRIST_TIE_PX` (those refits of cam01 at 30 fps
came within 0.7-1 px; taken, its joint-frames turning > 45 degrees went from 1.1 to 0.6%; cam01 from 59.3 to
59.9 mm, at half scale from 60.5 to 57.6, each other variant of cam01 and cam03 within 0.1 mm). A frame that
keeps its fit takes the twists of its turned bones from the neighbour (`untwisted`): a twist handed between a joint
and its child (a thigh turned one way about itself and the shin back) moves no keypoint, so the image cannot
choose it.
What turns remain are scored over a few frames (`bridged`): a frame (or up to `BRIDGE_FRAMES`) caught between two
turns, in neither resolution of its neighbours, is fitted again from one side, one frame from the next, and takes
those refits where they remove joint-turns, each worth more than the `TURN_PX` of mean reprojection they add in
all. A switch on its own stays (a bridge would only move it, except off the ends of the frames), and so does a
switch the image shows for longer (each frame refitted adds its error). (The two-person take's woman at 30
frames/s: frames 18-25 seen from behind raising both arms, a switch of both arms' depth with a frame between the
two: 1.3% of joint-frames turning > 45 degrees, 0.6% with the bridges. Taking refits that reproject closer where
they remove no turn, and so move a switch, took cam01 at 30 frames/s from 59.1 to 62.6 mm PA-MPJPE: from a
neighbour's pose, a refit's prior no longer holds the frame's own start from the BlazePose 3D.)
Before all this, in every frame of a fitted run, the neck and the collars hand their twists on to the head and the
shoulders (`girdle_untwisted`): ball joints both, so the pose is the one the keypoints and the children's
orientations give.
"""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

import smplx_jax
from jaxmocap.compile_cache import disk_jit
from jaxmocap.integrate import FitConfig, FitResult
from jaxmocap.integrate.fitting import fit_one, lens_arrays, openpose_keypoint_model
from jaxmocap.integrate.motion_arrays import reprojection_errors
from jaxmocap.pipeline.records import Bodies
from smplx_jax import constants
from smplx_jax.rotations import rotmat_to_rotvec

TURN_DEG = 45.0  # a body joint turning more than this from one frame to the next
TIE_PX = 0.01  # a refit reprojecting within this of the frame's own fit ties with it (float32 round-off)
WRIST_TIE_PX = 1.0  # the same for a refit of the wrists alone (the fingers can bend to match either turn)
WRISTS = (20, 21)  # SMPL-X joints
BRIDGE_FRAMES = 3  # `bridged`: at most this many frames refitted to bridge a turn
TURN_PX = 0.25  # `bridged`: a joint's turn between two frames is worth this much more mean reprojection (pixels)
# (joint, its one child) of the body's 22 SMPL-X joints, parents first: hips to feet, the spine, neck and head,
# collars to wrists (the pelvis, the top of the spine, the wrists have several children; the feet and head none)
BONES = ((1, 4), (2, 5), (3, 6), (4, 7), (5, 8), (6, 9), (7, 10), (8, 11), (12, 15), (13, 16), (14, 17), (16, 18),
         (17, 19), (18, 20), (19, 21))
GIRDLE = ((12, 15), (13, 16), (14, 17))  # the neck and head, the collars and shoulders: ball joints both


def rodrigues(rotvecs: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)``: the rotations of axis-angles ``(..., 3)``, in float64 (NumPy: called once per frame across
    a turn, where an eager JAX call would cost milliseconds)."""
    rotvecs = np.asarray(rotvecs, np.float64)
    angle = np.linalg.norm(rotvecs, axis=-1, keepdims=True)
    x, y, z = np.moveaxis(np.divide(rotvecs, angle, out=np.zeros_like(rotvecs), where=angle > 0), -1, 0)
    zero = np.zeros_like(x)
    k = np.stack([np.stack([zero, -z, y], -1), np.stack([z, zero, -x], -1), np.stack([-y, x, zero], -1)], -2)
    angle = angle[..., None]
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * k @ k


def body_rotmats(global_orient: np.ndarray, body_pose: np.ndarray) -> np.ndarray:
    """``(T, 22, 3, 3)``: the global orientation ``(T, 3)`` and the 21 body joints' rotations ``(T, 21, 3)``."""
    return rodrigues(np.concatenate([np.asarray(global_orient)[:, None], np.asarray(body_pose)], 1))


def turns_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``(..., J)`` the angle, degrees, between each joint's rotations ``a`` and ``b`` ``(..., J, 3, 3)``: of
    ``R = a^T b``, ``atan2(|R - R^T| / 2, (trace R - 1) / 2)`` (NumPy: called once per frame across a turn)."""
    r = np.swapaxes(a, -1, -2) @ b
    sin = 0.5 * np.linalg.norm(np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                                         r[..., 1, 0] - r[..., 0, 1]], -1), axis=-1)
    return np.degrees(np.arctan2(sin, 0.5 * (np.trace(r, axis1=-2, axis2=-1) - 1.0)))


def _twist_angle(rotmat: np.ndarray, axis: np.ndarray) -> float:
    """The angle, radians, of the twist about the unit ``axis`` in ``rotmat`` (its swing-twist decomposition:
    ``2 atan2(v . axis, w)`` of its quaternion ``(w, v)``, taken by Shepperd's method: exact at half a turn)."""
    r = rotmat
    largest = int(np.argmax([np.trace(r), r[0, 0], r[1, 1], r[2, 2]]))
    if largest == 0:
        s = 2.0 * np.sqrt(1.0 + np.trace(r))
        w, v = s / 4, np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]]) / s
    else:
        i = largest - 1
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        w, v = (r[k, j] - r[j, k]) / s, np.empty(3)
        v[i], v[j], v[k] = s / 4, (r[j, i] + r[i, j]) / s, (r[k, i] + r[i, k]) / s
    return float(2.0 * np.arctan2(np.sign(w or 1.0) * (v @ axis), abs(w)))  # the quaternion with w >= 0


def untwisted(rotmats: np.ndarray, neighbour: np.ndarray, bone_axes: np.ndarray, turned: np.ndarray) -> np.ndarray:
    """A frame's body rotations ``(22, 3, 3)`` where a joint ``turned (22,)`` from the ``neighbour`` frame's by a
    twist about its bone (`BONES`; the rest direction ``bone_axes (22, 3)``, unit): that twist handed to its child,
    so the joint no longer turns by more than `TURN_DEG`. Every joint's position and every child's orientation
    stay, so no keypoint moves; a turn that is not mostly twist (a limb swung) is left as it is."""
    out = np.array(rotmats, np.float64, copy=True)
    for joint, child in BONES:
        if not turned[joint]:
            continue
        angle = _twist_angle(out[joint].T @ neighbour[joint], bone_axes[joint])
        handed = _twist_handed_on(out[joint], out[child], bone_axes[joint], angle)
        if turns_deg(handed[0][None], neighbour[joint][None])[0] <= TURN_DEG:
            out[joint], out[child] = handed
    return out


def _twist_handed_on(joint: np.ndarray, child: np.ndarray, axis: np.ndarray, angle: float):
    """A joint's rotation ``(3, 3)`` twisted by ``angle`` about its bone's unit ``axis``, and its child's turned
    back by as much: the child's orientation and every joint's position stay, so no keypoint moves."""
    twist = rodrigues(axis * angle)
    return joint @ twist, twist.T @ child


def girdle_untwisted(model: smplx_jax.BodyModel, bodies: Bodies) -> Bodies:
    """``bodies`` with the twist of the neck and of each collar about its bone (`GIRDLE`) handed to its child (the
    head, the shoulder) in every valid frame, as `untwisted` hands a twist on: every joint's position and every
    child's orientation stay, so no keypoint moves, and a fit leaves that twist to chance (the two-person take's
    woman at 30 frames/s: neck, collars and their children turned by 125-165° from one frame to the next). With
    none there, the pose that the keypoints and the children's orientations give is one."""
    valid = np.flatnonzero(bodies.valid)
    if not len(valid):
        return bodies
    axes = bone_axes(model, np.asarray(bodies.params.betas[valid[0]], np.float64))
    rotmats = body_rotmats(bodies.params.global_orient[valid], bodies.params.body_pose[valid])
    for frame in rotmats:
        for joint, child in GIRDLE:
            frame[joint], frame[child] = _twist_handed_on(frame[joint], frame[child], axes[joint],
                                                          -_twist_angle(frame[joint], axes[joint]))
    return _with_body_rotations(bodies, valid, rotmats)


def bone_axes(model: smplx_jax.BodyModel, betas: np.ndarray) -> np.ndarray:
    """``(22, 3)``: each `BONES` joint's unit direction to its child in the rest pose of the shape ``betas``."""
    rest = np.asarray(model.joint_template, np.float64) + np.asarray(model.joint_shapedirs)[..., :len(betas)] @ betas
    axes = np.zeros((22, 3))
    for joint, child in BONES:
        axes[joint] = (rest[child] - rest[joint]) / np.linalg.norm(rest[child] - rest[joint])
    return axes


def _start(params: smplx_jax.SMPLXParams, k: int, neighbour: int, turned: np.ndarray):
    """The refit of frame ``k`` across a turn of the joints ``turned`` (22,) from frame ``neighbour``: its start
    (one body), free joints (55,) and tie. A turn of the body (the global orientation, a joint of the spine, legs
    or arms: how the body lies in depth): the neighbour's pose, every joint free, `TIE_PX`. A turn of the wrists
    alone (the hand's own ambiguity): frame ``k``'s pose with the wrists' rotations the neighbour's, those and
    their hands' fingers free (the rest of the fit, and what its start took from the 3D landmarks, kept),
    `WRIST_TIE_PX`."""
    one = jax.tree.map(lambda a: np.array(a[k]), params)
    free = np.zeros(55, np.float32)
    if turned[:WRISTS[0]].any():
        one, free[:] = jax.tree.map(lambda a: np.array(a[neighbour]), params), 1.0
        return one, free, TIE_PX
    one.body_pose[turned[1:]] = params.body_pose[neighbour][turned[1:]]
    free[:22] = turned
    free[list(constants.LEFT_HAND_JOINTS)], free[list(constants.RIGHT_HAND_JOINTS)] = turned[list(WRISTS)]
    return one, free, WRIST_TIE_PX


@disk_jit(static_argnames="config")
def _refit(km, keypoints, pose, betas, free, lens, config: FitConfig) -> FitResult:
    """One frame fitted again from ``pose (55, 3)`` with its shape ``betas`` held, in one compiled call (the
    refits run one after another, each from its neighbour's outcome)."""
    return fit_one(km, keypoints.astype(pose.dtype), pose, betas, None, lens, config, free=free.astype(pose.dtype),
                   fit_betas=jnp.zeros((), pose.dtype), differentiable=False)


def coherent(model: smplx_jax.BodyModel, bodies: Bodies, keypoints_2d: np.ndarray, lens, config: FitConfig | None,
             iterations: int = 20) -> Bodies:
    """``bodies`` with each frame across a turn of more than `TURN_DEG` fitted again from its neighbour, then the
    turns left `bridged` (module docstring); ``lens`` the run's pinhole camera, ``config`` the fit's (None, as after
    copy-and-paste: unchanged). Each refit is one compiled call on one frame (`_refit`)."""
    frames = np.flatnonzero(bodies.valid).tolist()
    if config is None or len(frames) < 2:
        return bodies
    rotmats = body_rotmats(bodies.params.global_orient, bodies.params.body_pose)
    turns = turns_deg(rotmats[frames[:-1]], rotmats[frames[1:]]).max(1)
    runs = np.split(np.arange(len(frames)), np.flatnonzero(turns > TURN_DEG) + 1)
    if len(runs) == 1:
        return bodies
    longest = max(runs, key=len)
    errors = reprojection_errors(model, bodies.params, bodies.camera_scale, bodies.camera_trans, keypoints_2d, *lens)
    out = bodies
    steps = [(frames[i], frames[i - 1]) for i in range(longest[-1] + 1, len(frames))] + [
        (frames[i], frames[i + 1]) for i in range(longest[0] - 1, -1, -1)]
    axes = bone_axes(model, np.asarray(bodies.params.betas[frames[0]], np.float64))
    km, fit_lens = openpose_keypoint_model(model), lens_arrays(lens[0], lens[1], model.joint_template.dtype)
    config = dataclasses.replace(config, iterations=iterations)
    refit = functools.partial(_refit_from, model, keypoints_2d, lens, km, fit_lens, config)
    for k, neighbour in steps:
        turned = turns_deg(rotmats[k], rotmats[neighbour]) > TURN_DEG
        if not turned.any():
            continue
        one, error, tie = refit(out, k, neighbour, turned)
        if one is not None and error <= errors[k] + tie:  # (each frame is refitted once here: errors[k] is its own)
            out, rotmats[k] = _with_frame(out, k, one), body_rotmats(one.params.global_orient, one.params.body_pose)[0]
            errors[k] = error
        else:  # the frame keeps its fit, with the turned bones' twists the neighbour's (no keypoint moves)
            handed = untwisted(rotmats[k], rotmats[neighbour], axes, turned)
            if not np.array_equal(handed, rotmats[k]):  # a bone handed its twist on
                rotmats[k], out = handed, _with_body_rotations(out, k, handed)
    return bridged(out, rotmats, frames, errors, refit)  # (a frame given twists kept its error: no keypoint moved)


def _refit_from(model, keypoints_2d, lens, km, fit_lens, config, bodies: Bodies, k: int, neighbour: int,
                turned: np.ndarray):
    """Frame ``k`` of ``bodies`` fitted again from frame ``neighbour`` across the turn of the joints ``turned``
    (`_start`): the refit (one frame; None where the fit failed), its reprojection error and its tie."""
    start, free, tie = _start(bodies.params, k, neighbour, turned)
    result = jax.tree.map(lambda a: np.asarray(a)[None], _refit(
        km, keypoints_2d[k], start.full_pose(), start.betas, free, fit_lens, config))
    one = Bodies(result.params, result.camera_scale, result.camera_trans, np.ones(1, bool))
    error = reprojection_errors(model, one.params, one.camera_scale, one.camera_trans, keypoints_2d[k:k + 1],
                                *lens)[0]
    return (one if bool(result.valid[0]) else None), float(error), tie


def _turn_count(rotmats: np.ndarray) -> int:
    """How many joints turn by more than `TURN_DEG` between consecutive frames of ``rotmats (T, 22, 3, 3)``."""
    return int(np.sum(turns_deg(rotmats[:-1], rotmats[1:]) > TURN_DEG))


def bridged(bodies: Bodies, rotmats: np.ndarray, frames: list[int], errors: np.ndarray, refit) -> Bodies:
    """``bodies`` with each turn that `coherent` left bridged where that is cheap: from the frames on one side of
    it, the next frames (up to `BRIDGE_FRAMES`) fitted again one from another (``refit(bodies, k, neighbour,
    turned)``: the refit, its error, its tie), and taken where they remove joint-turns, worth more than the
    reprojection they add (`TURN_PX` each). A depth switch that the image shows for longer stays (the error
    added grows with every frame); a frame or two caught between two resolutions joins one of them."""
    rotmats = rotmats.copy()
    for i in range(len(frames) - 1):
        if _turn_count(rotmats[frames[i:i + 2]]) == 0:
            continue
        best = (0.0, None)
        for step in (1, -1):
            anchor = i if step > 0 else i + 1
            trial, trial_rotmats, trial_errors = bodies, rotmats.copy(), np.array(errors, np.float64)
            for width in range(1, BRIDGE_FRAMES + 1):
                j = anchor + step * width
                if not 0 <= j < len(frames):
                    break
                k, neighbour = frames[j], frames[j - step]
                turned = turns_deg(trial_rotmats[k], trial_rotmats[neighbour]) > TURN_DEG
                if not turned.any():
                    break
                one, error, _ = refit(trial, k, neighbour, turned)
                if one is None:
                    break
                trial, trial_errors[k] = _with_frame(trial, k, one), error
                trial_rotmats[k] = body_rotmats(one.params.global_orient, one.params.body_pose)[0]
                end = min(max(j + step, 0), len(frames) - 1)  # the pair beyond the refits, where there is one
                span = frames[min(anchor, end):max(anchor, end) + 1]
                removed = _turn_count(rotmats[span]) - _turn_count(trial_rotmats[span])
                gain = TURN_PX * removed - float(np.sum(trial_errors[span] - errors[span]))
                if removed > 0 and gain > best[0]:
                    best = (gain, (trial, trial_rotmats.copy(), trial_errors.copy()))
        if best[1] is not None:
            bodies, rotmats, errors = best[1]
    return bodies


def _with_frame(bodies: Bodies, k: int, one: Bodies) -> Bodies:
    """``bodies`` with frame ``k`` that of ``one`` (one frame)."""
    return jax.tree.map(lambda a, b: np.concatenate([a[:k], b, a[k + 1:]]), bodies, one)


def _with_body_rotations(bodies: Bodies, frames: int | np.ndarray, rotmats: np.ndarray) -> Bodies:
    """``bodies`` with the global orientation and body pose of ``frames`` (a frame, or an index array) those of
    ``rotmats`` (``(22, 3, 3)``, or one such per frame)."""
    rotvecs = np.asarray(rotmat_to_rotvec(np.asarray(rotmats, np.float32)))
    params = bodies.params
    global_orient, body_pose = np.array(params.global_orient), np.array(params.body_pose)
    global_orient[frames], body_pose[frames] = rotvecs[..., 0, :], rotvecs[..., 1:, :]
    return dataclasses.replace(bodies, params=params.replace(global_orient=global_orient, body_pose=body_pose))
