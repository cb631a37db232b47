"""Accuracy on real footage (docs/BENCHMARKS.md, "Accuracy on real footage"): monocular runs on views of Pose2Sim's
single-person take, scored against the multi-view 3D reference beside BlazePose's own monocular 3D (the world
landmarks the fit starts from), stage by stage: BlazePose, the clip fit's start (IK), the motion (what
``jaxmocap run`` writes).

    python bench/accuracy.py [--views cam01 cam03] [--variants all | mirror rotate90 roll15 roll30 crop half 30fps pan]
        [--landmarks heavy full lite] [--chunk N] [--out bench/results] [--sheet docs/accuracy_worst_frames.png]
        (or: jaxmocap bench --only accuracy)

Variants (`--variants`) stand in for the views we don't have: each view's video as another camera would have given
it (`write_variant`), run and scored the same way against the reference transformed alike (`variant_reference`):
``mirror`` (left and right swap: the mirrored reference scores it), ``rotate90`` (a phone held sideways),
``roll15``/``roll30`` (a camera held askew: the frame turned by that many degrees about its centre, on a canvas
that holds all of it), ``crop`` (the half of the frame around the person), ``half`` (scaled by 0.5), ``30fps``
(every other frame), ``pan`` (a window of three quarters of the width sliding across the frame over the clip: a
camera that pans). ``--landmarks``: each case is run with each BlazePose landmark model given (`jaxmocap run
--landmarks`), and the table puts them side by side.

Metrics, per frame where the reference has at least 8 of its 12 limb joints (L/R shoulder, elbow, wrist, hip, knee,
ankle): PA-MPJPE (mm, after the best similarity transform of that frame), WA-MPJPE (mm, after one similarity
transform over every scored frame of the clip: depth drift, a wandering root and a changing scale count), knee and
elbow flexion MAE (degrees,
alignment-free), acceleration error (mm/frame^2, second differences of the aligned joints against the reference's,
over three consecutive scored frames); for the motion: frames valid, median and > 40 px share of the 2D
reprojection error, the frame-to-frame change of the stored rotations (global and body joints, at 60 fps), and the
share of finger joints bent backwards by more than 10 degrees; the share of frames whose global orientation turns by
more than 45 degrees; the number of identities the run gave the one person. The world frame (motion.npz's world
keys): the floor's normal against the room's up (the calibration; ``pan``: seen from its first window), WA-MPJPE
of the world joints, while a reference ankle stands still our ankle's movement per frame beside the reference's own,
the heel and toe frames in contact and those of them within 2 cm of the floor, the lowest sole. ``pan`` is also run
with ``--camera static``: the world motion of each run against the static view's (`panning_scores`).
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from train.metrics import procrustes_align  # noqa: E402

DATA = ROOT / "tests" / "data"
VIEWS = {"cam01": ROOT / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4",
         "cam03": DATA / "pose2sim_single_cam03.mp4"}
REFERENCE = DATA / "pose2sim_single_reference_3d.npz"
CALIBRATION = DATA / "pose2sim_Calib.qca.txt"
# SMPL-X joints in the reference's order: L/R shoulder, elbow, wrist, hip, knee, ankle
SMPLX_LIMB_JOINTS = (16, 17, 18, 19, 20, 21, 1, 2, 4, 5, 7, 8)
BLAZEPOSE_LIMB_LANDMARKS = (11, 12, 13, 14, 15, 16, 23, 24, 25, 26, 27, 28)
MIN_JOINTS = 8
# (proximal, middle, distal) of the reference's order: L/R knee, L/R elbow
FLEXION_TRIPLES = ((6, 8, 10), (7, 9, 11), (0, 2, 4), (1, 3, 5))


@dataclass
class Score:
    frames_scored: int
    pa_mpjpe_mm: float
    wa_mpjpe_mm: float
    flexion_mae_deg: float
    accel_error_mm: float


def load_reference(path=REFERENCE) -> np.ndarray:
    """``(T, 12, 3)`` metres, NaN where missing."""
    with np.load(path) as f:
        return f["joints3d"].astype(np.float64)


def _flexion_deg(joints: np.ndarray) -> np.ndarray:
    """``(T, 4)`` flexion angles (180 - the angle at the middle joint), degrees."""
    out = []
    for a, b, c in FLEXION_TRIPLES:
        u, v = joints[:, a] - joints[:, b], joints[:, c] - joints[:, b]
        angle = np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.sum(u * v, -1))
        out.append(180.0 - np.degrees(angle))
    return np.stack(out, 1)


def score(joints: np.ndarray, reference: np.ndarray) -> tuple[Score, np.ndarray]:
    """Score ``(T, 12, 3)`` joints (any units proportional to metres, NaN where missing) against the reference;
    also returns each frame's PA-MPJPE in mm (NaN where not scored)."""
    present = np.all(np.isfinite(reference), -1) & np.all(np.isfinite(joints), -1)
    scored = present.sum(1) >= MIN_JOINTS
    aligned = np.full_like(reference, np.nan)
    per_frame = np.full(len(reference), np.nan)
    for t in np.flatnonzero(scored):
        aligned[t] = procrustes_align(joints[t], np.nan_to_num(reference[t]), present[t])
        per_frame[t] = 1000 * np.mean(np.linalg.norm(aligned[t] - reference[t], axis=-1)[present[t]])
    wa_mpjpe = whole_clip_error_mm(joints[scored], reference[scored], present[scored])
    flexion_error = np.abs(_flexion_deg(joints) - _flexion_deg(reference))[scored]
    accel = []
    for t in range(1, len(reference) - 1):
        if scored[t - 1:t + 2].all():
            ok = present[t - 1:t + 2].all(0)
            a = aligned[t - 1] - 2 * aligned[t] + aligned[t + 1]
            r = reference[t - 1] - 2 * reference[t] + reference[t + 1]
            accel.append(1000 * np.linalg.norm(a - r, axis=-1)[ok])
    return Score(int(scored.sum()), float(np.nanmean(per_frame)), wa_mpjpe, float(np.nanmean(flexion_error)),
                 float(np.mean(np.concatenate(accel))) if accel else float("nan")), per_frame


def whole_clip_error_mm(joints: np.ndarray, reference: np.ndarray, present: np.ndarray) -> float:
    """WA-MPJPE: the mean distance (mm) of ``(T, J, 3)`` joints to the reference after ONE similarity transform
    of every frame's joints together (over the joints ``present (T, J)``); NaN without any."""
    if not present.any():
        return float("nan")
    aligned = procrustes_align(joints.reshape(-1, 3), np.nan_to_num(reference).reshape(-1, 3), present.ravel())
    return float(1000 * np.mean(np.linalg.norm(aligned - np.nan_to_num(reference).reshape(-1, 3), axis=-1)
                                [present.ravel()]))


def rotation_changes_deg(global_orient: np.ndarray, body_pose: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Angle between consecutive frames' rotations of the global orientation and the 21 body joints, degrees,
    over consecutive valid frames: ``(pairs, 22)`` (of ``R = a^T b``, ``atan2(|R - R^T| / 2, (trace R - 1) / 2)``)."""
    from smplx_jax.rotations import rotvec_to_rotmat

    rotvecs = np.concatenate([np.asarray(global_orient)[:, None], np.asarray(body_pose)], 1)
    rot = np.asarray(rotvec_to_rotmat(rotvecs.astype(np.float32)), np.float64)
    pairs = np.flatnonzero(valid[:-1] & valid[1:])
    r = np.swapaxes(rot[pairs], -1, -2) @ rot[pairs + 1]
    sin = 0.5 * np.linalg.norm(np.stack([r[..., 2, 1] - r[..., 1, 2], r[..., 0, 2] - r[..., 2, 0],
                                         r[..., 1, 0] - r[..., 0, 1]], -1), axis=-1)
    return np.degrees(np.arctan2(sin, 0.5 * (np.trace(r, axis1=-2, axis2=-1) - 1.0)))


def rotation_coherence(motion: dict) -> dict:
    changes = rotation_changes_deg(motion["global_orient"], motion["body_pose"], motion["valid"])
    return dict(rotation_change_median_deg=float(np.median(changes)),
                rotation_change_over_45deg=float(np.mean(changes > 45)),
                global_turn_over_45deg=float(np.mean(changes[:, 0] > 45)),
                global_turn_largest_deg=float(changes[:, 0].max(initial=0.0)))


VARIANTS = ("mirror", "rotate90", "roll15", "roll30", "crop", "half", "30fps", "pan")
PAN_WIDTH = 0.75  # of the frame's width: the window of the ``pan`` variant
MIRRORED_LIMBS = np.arange(12).reshape(6, 2)[:, ::-1].ravel()  # the reference's left and right exchanged


def write_variant(video: Path, kind: str, out: Path, person_x: float) -> Path:
    """``video`` as another camera would have given it (`VARIANTS`), written to ``out`` (mp4); ``person_x``: the
    person's median horizontal position in pixels (``crop`` keeps the half of the width around it)."""
    import cv2

    from jaxmocap.frame_source import open_media

    media, frames = open_media(video, 0, None, 2 if kind == "30fps" else 1)
    width, height = media.size
    left = int(np.clip(person_x - width / 4, 0, width - width // 2))
    if kind.startswith("roll"):  # turned about the centre onto a canvas holding the whole frame
        angle = np.radians(float(kind[4:]))
        size = (int(np.ceil(width * np.cos(angle) + height * np.sin(angle))),
                int(np.ceil(width * np.sin(angle) + height * np.cos(angle))))
        turn = cv2.getRotationMatrix2D((width / 2, height / 2), float(kind[4:]), 1.0)
        turn[:, 2] += (np.asarray(size) - (width, height)) / 2
    pan = int(PAN_WIDTH * width)

    def transformed(index, frame):
        if kind == "mirror":
            return cv2.flip(frame, 1)
        if kind == "rotate90":
            return cv2.rotate(frame, cv2.ROTATE_90_CLOCKWISE)
        if kind.startswith("roll"):
            return cv2.warpAffine(frame, turn, size, flags=cv2.INTER_LINEAR)
        if kind == "crop":
            return np.ascontiguousarray(frame[:, left:left + width // 2])
        if kind == "half":
            return cv2.resize(frame, (width // 2, height // 2), interpolation=cv2.INTER_AREA)
        if kind == "pan":
            x0 = round((width - pan) * index / max(media.frame_count - 1, 1))
            return np.ascontiguousarray(frame[:, x0:x0 + pan])
        return frame

    writer = None
    for index, frame in frames:
        frame = transformed(index, frame)
        if writer is None:
            writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"mp4v"), media.fps, frame.shape[1::-1])
        writer.write(frame)
    writer.release()
    return out


def variant_reference(reference: np.ndarray, kind: str) -> np.ndarray:
    """The 3D reference of a variant: mirrored (x negated, left and right exchanged) or every other frame."""
    if kind == "mirror":
        return reference[:, MIRRORED_LIMBS] * np.array([-1.0, 1.0, 1.0])
    return reference[::2] if kind == "30fps" else reference


def room_up(view: str, path=CALIBRATION) -> np.ndarray:
    """The room's up direction seen from the camera of ``view`` (x right, y down, z forward), from the
    calibration (tests/data/SOURCES.md)."""
    import xml.etree.ElementTree as ElementTree

    camera = next(c for c in ElementTree.parse(path).getroot().iter("camera") if c.get("serial") == view)
    rows = camera.find("transform").attrib
    world_to_camera = np.diag([1.0, -1.0, -1.0]) @ np.array([[float(rows[f"r{i}{j}"]) for j in "123"] for i in "123"])
    return world_to_camera[:, 2]


def variant_up(up: np.ndarray, kind: str | None, size: tuple[int, int]) -> np.ndarray:
    """The room's up seen by a variant's camera (its first frame's, for ``pan``), of a view of ``size`` (width,
    height): mirrored (x negated), turned about the optical axis as its frames were (``rotate90``: clockwise;
    ``roll``: OpenCV's counter-clockwise degrees), or, for ``pan``, turned about the vertical axis to look through
    the first window's centre (through the run's focal length)."""
    from jaxmocap.integrate.camera import default_focal_length

    if kind == "pan":
        window = (int(PAN_WIDTH * size[0]), size[1])
        aside = np.arctan2(window[0] / 2 - size[0] / 2, default_focal_length(window))
        cos, sin = np.cos(aside), np.sin(aside)
        return np.array([[cos, 0.0, sin], [0.0, 1.0, 0.0], [-sin, 0.0, cos]]).T @ up
    if kind == "mirror":
        return up * np.array([-1.0, 1.0, 1.0])
    angle = -np.pi / 2 if kind == "rotate90" else np.radians(float(kind[4:])) if kind and kind.startswith("roll") \
        else 0.0
    cos, sin = np.cos(angle), np.sin(angle)
    return np.array([cos * up[0] + sin * up[1], -sin * up[0] + cos * up[1], up[2]])


def floor_scores(motion: dict, up: np.ndarray | None) -> dict:
    """The motion's floor against the room's ``up``: the angle between their up directions (degrees; None
    without a floor or a known up) and the share of heel and toe frames in contact."""
    if "floor" not in motion or up is None:
        return dict(floor_angle_deg=None, contact_share=None)
    normal = np.asarray(motion["floor"][:3], np.float64)
    cos = normal @ up / np.linalg.norm(normal) / np.linalg.norm(up)
    return dict(floor_angle_deg=float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))),
                contact_share=float(np.mean(motion["contact"][np.asarray(motion["valid"])])))


ANKLES = (10, 11)  # the reference's (and `SMPLX_LIMB_JOINTS`') left and right ankle
CONTACT_TOLERANCE_M = 0.02  # a heel or toe in contact within this of the floor; none below it by more


def world_joints(motion: dict) -> np.ndarray:
    """``(T, 127, 3)`` the SMPL-X joints of a motion in its world frame (its ``world_*`` keys; NaN where not
    valid)."""
    return body_joints_of(dict(motion, global_orient=motion["world_global_orient"], transl=motion["world_transl"]))


def body_joints_of(motion: dict) -> np.ndarray:
    """``(T, 127, 3)`` the SMPL-X joints of a motion (NaN where not valid)."""
    import smplx_jax
    from jaxmocap.integrate.motion_arrays import body_joints
    from jaxmocap.motion import motion_params

    model = smplx_jax.load_model(smplx_jax.default_model_path())
    joints = body_joints(model, motion_params(motion, model.num_expression)).astype(np.float64)
    return np.where(np.asarray(motion["valid"])[:, None, None], joints, np.nan)


def still_frames(ankles: np.ndarray, fps: float) -> np.ndarray:
    """``(T, 2)`` where each of the reference's ankles ``(T, 2, 3)`` stands still: slower than
    `ground.REST_SPEED_M_S` (the run's own rule: far below a step's speed, above what the reference's 1-2 cm of
    noise gives over the window) over `ground.SPEED_WINDOW_S` about the frame."""
    from jaxmocap.integrate.ground import REST_SPEED_M_S, SPEED_WINDOW_S

    half = max(1, round(SPEED_WINDOW_S * fps / 2))
    speed = np.full(ankles.shape[:2], np.inf)
    speed[half:-half] = np.linalg.norm(ankles[2 * half:] - ankles[:-2 * half], axis=-1) * fps / (2 * half)
    return np.nan_to_num(speed, nan=np.inf) < REST_SPEED_M_S


def world_scores(motion: dict, reference: np.ndarray) -> dict:
    """The world frame against the reference: WA-MPJPE of the world joints (mm); while a reference ankle stands
    still (`still_frames`), our ankle's mean frame-to-frame movement after the whole-clip alignment over the
    reference's own there (``sliding_ratio``; both in mm per frame); the share of heel and toe frames in contact
    whose sole is within `CONTACT_TOLERANCE_M` of the floor and the lowest sole of any valid frame (cm)."""
    if "world_transl" not in motion:
        return dict(world_wa_mpjpe_mm=None, sliding_ratio=None, still_ankle_mm=None, reference_still_mm=None,
                    contact_on_floor=None, lowest_sole_cm=None)
    import smplx_jax
    from jaxmocap.integrate.ground import FOOT_JOINTS, sole_heights

    joints = world_joints(motion)
    limbs = joints[:, SMPLX_LIMB_JOINTS]
    present = np.all(np.isfinite(reference), -1) & np.all(np.isfinite(limbs), -1)
    scored = present.sum(1) >= MIN_JOINTS
    wa = whole_clip_error_mm(limbs[scored], reference[scored], present[scored])
    aligned = np.full_like(limbs, np.nan)
    aligned[scored] = procrustes_align(limbs[scored].reshape(-1, 3), np.nan_to_num(reference[scored]).reshape(-1, 3),
                                       present[scored].ravel()).reshape(-1, 12, 3)
    still = still_frames(reference[:, ANKLES], float(motion["fps"]))
    pairs = still[:-1] & still[1:] & scored[:-1, None] & scored[1:, None]
    moved = [1000 * np.linalg.norm(np.diff(x[:, ANKLES], axis=0), axis=-1)[pairs] for x in (aligned, reference)]
    valid = np.asarray(motion["valid"])
    model = smplx_jax.load_model(smplx_jax.default_model_path())
    soles = joints[:, FOOT_JOINTS, 1] - sole_heights(model, motion["betas"][np.argmax(valid)])
    contact = np.asarray(motion["contact"]) & valid[:, None]
    return dict(world_wa_mpjpe_mm=wa, sliding_ratio=float(np.nanmean(moved[0]) / np.nanmean(moved[1])),
                still_ankle_mm=float(np.nanmean(moved[0])), reference_still_mm=float(np.nanmean(moved[1])),
                contact_on_floor=float(np.mean(np.abs(soles[contact]) <= CONTACT_TOLERANCE_M))
                if contact.any() else None,
                lowest_sole_cm=float(100 * np.min(soles[valid])) if valid.any() else None)


def panning_scores(turning: dict, held: dict, static: dict) -> dict:
    """A panning camera's world motion against the static view's: WA-MPJPE (mm, one similarity over the clip) of
    the limb joints in the world frame, of the run that measured the camera's turns (``turning``) and of the same
    clip held still (``held``, ``--camera static``), over the frames valid in both; and how far the camera turned
    (degrees, the largest turn from the first frame)."""
    reference = world_joints(static)[:, SMPLX_LIMB_JOINTS]

    def against(motion):
        joints = world_joints(motion)[:, SMPLX_LIMB_JOINTS]
        return whole_clip_error_mm(joints, reference, np.all(np.isfinite(joints) & np.isfinite(reference), -1))

    turns = np.asarray(turning["camera_from_world"][:, :3, :3], np.float64)
    cos = (np.trace(np.swapaxes(turns[:1], 1, 2) @ turns, axis1=1, axis2=2) - 1) / 2
    return dict(turned_deg=float(np.degrees(np.arccos(np.clip(cos, -1, 1)).max())),
                world_vs_static_mm=against(turning), held_still_vs_static_mm=against(held))


def video_size(video: Path) -> tuple[int, int]:
    """``(width, height)`` of a video's frames."""
    from jaxmocap.frame_source import open_media

    return tuple(open_media(video, 0, 1, 1)[0].size)


def fingers_bent_backwards(motion: dict, tolerance_deg: float = 10.0) -> float:
    """The share of finger joint-frames (index to ring, both hands, valid frames) bent backwards, against their
    flexion, by more than ``tolerance_deg``."""
    from jaxmocap.integrate.least_squares import FINGER_BACKWARDS

    hands = np.concatenate([motion["left_hand_pose"], motion["right_hand_pose"]], 1)[np.asarray(motion["valid"])]
    backwards = np.stack([sign * hands[:, j - 25, axis] for j, axis, sign in FINGER_BACKWARDS], 1)
    return float(np.mean(np.degrees(backwards) > tolerance_deg))


@dataclass
class Stages:
    """One view's per-frame results: BlazePose's limb landmarks, the clip fit's start (IK from the landmarks,
    placed in the camera), the motion."""

    blazepose: np.ndarray  # (T, 12, 3) world landmarks, NaN where no person
    ik: dict  # motion-like arrays of the start (global_orient, body_pose, ..., valid)
    motion: dict  # as `jaxmocap run` writes it
    identities: int  # the people the run found (one in this take)


def run_stages(video: Path, work: Path, end: int | None = None, landmarks: str = "heavy",
               chunk_size: int | None = None, camera: str = "turns") -> Stages:
    """``jaxmocap run`` on ``video`` (frames up to ``end``, ``chunk_size`` frames a chunk or the run's default,
    ``--camera camera``; its motion.npz), and the stages before the clip fit from what the run itself observed,
    chunk by chunk (`run`'s ``observed``): BlazePose's world landmarks (left and right put back where the detector
    exchanged them, as the fit takes them) and the fit's start. The take has one person: each frame's is the lowest
    id found."""
    import jax

    import smplx_jax
    from jaxmocap.motion import lens, read_motion
    from jaxmocap.pipeline import RunConfig, motion_arrays, run
    from jaxmocap.pipeline.tracks import Track, frames_where
    from jaxmocap.pipeline.whole_clip import with_start

    model = smplx_jax.load_model(smplx_jax.default_model_path())
    chunks = []  # per chunk: (BlazePose's limbs, the person's track)

    def observed(chunk, people):
        count = len(chunk.frame_index)
        part = (np.full((count, 12, 3), np.nan), Track.absent(count, model))
        for person_id in sorted(people, reverse=True):
            obs, track = people[person_id], chunk.people[person_id]
            part = frames_where(obs.found, (obs.body_world[:, BLAZEPOSE_LIMB_LANDMARKS, :3], track), part)
        chunks.append(part)

    chunking = {} if chunk_size is None else {"chunk_size": chunk_size}
    run(RunConfig(video, end=end, overlay=False, progress=False, landmarks=landmarks, camera=camera, **chunking), work,
        observed=observed)
    motion = read_motion(work / "motion.npz")
    blazepose, track = jax.tree.map(lambda *a: np.concatenate(a), *chunks)
    start = with_start(model, track, lens(motion)).bodies
    return Stages(blazepose, motion_arrays(model, start, track.keypoints_2d, lens(motion)), motion,
                  len(list((work / "people").iterdir())))


def limb_joints(motion: dict) -> np.ndarray:
    """``(T, 12, 3)`` SMPL-X limb joints of a motion (NaN where not valid)."""
    return body_joints_of(motion)[:, SMPLX_LIMB_JOINTS]


def report_view(name: str, stages: Stages, reference: np.ndarray, up: np.ndarray | None = None) -> dict:
    rows = {"identities": stages.identities}
    for stage, joints in (("blazepose", stages.blazepose), ("ik", limb_joints(stages.ik)),
                          ("motion", limb_joints(stages.motion))):
        result, per_frame = score(joints, reference)
        rows[stage] = asdict(result) | {"per_frame_pa_mpjpe_mm": [None if np.isnan(v) else round(float(v), 1)
                                                                    for v in per_frame]}
        if stage != "blazepose":
            motion = getattr(stages, stage)
            rows[stage] |= rotation_coherence(motion) | dict(fingers_backwards=fingers_bent_backwards(motion))
            if stage != "ik":
                errors = np.asarray(motion["reprojection_error_px"])
                rows[stage] |= floor_scores(motion, up) | world_scores(motion, reference) | dict(
                    valid_share=float(np.mean(motion["valid"])),
                    reprojection_median_px=float(np.median(errors[np.asarray(motion["valid"])])),
                    reprojection_over_40px=float(np.mean(errors > 40)))
    return rows


def contact_sheet(path: Path, views: dict, motions: dict, per_frame: dict, count: int = 3) -> None:
    """The ``count`` worst frames of each view by PA-MPJPE: the mesh over the frame beside its side view."""
    import cv2
    import jax

    import smplx_jax
    from jaxmocap.frame_source import open_media
    from jaxmocap.motion import lens, motion_params
    from jaxmocap.overlay import Posed, body_up, mesh_over_frame, side_view

    model = smplx_jax.load_model(smplx_jax.default_model_path())
    faces = np.asarray(model.faces)
    forward = jax.jit(smplx_jax.forward)
    rows = []
    for name, video in views.items():
        errors = np.asarray(per_frame[name], float)
        worst = [int(t) for t in np.argsort(np.nan_to_num(errors, nan=-1.0))[::-1][:count]]
        _, frames = open_media(video, 0, None, 1)
        images = {i: frame for i, frame in frames if i in worst}
        motion = motions[name]
        tiles = []
        for t in worst:
            params = jax.tree.map(lambda a: a[t], motion_params(motion, model.num_expression))
            vertices = np.asarray(forward(model, params).vertices)
            scale = 480 / images[t].shape[0]
            left = mesh_over_frame(images[t], vertices, faces, float(motion["camera_scale"][t]),
                                   motion["camera_trans"][t], scale, *lens(motion))
            lo, hi = vertices.min(0), vertices.max(0)
            right = side_view([Posed(0, vertices, 1.0, np.zeros(2))], faces, left.shape[1::-1],
                              0.75 * left.shape[0] / (hi - lo).max(), (lo + hi) / 2,
                              up=body_up(motion["global_orient"][motion["valid"]]))
            tile = np.concatenate([left, right], axis=1)
            cv2.putText(tile, f"{name} frame {t}: {errors[t]:.0f} mm", (8, 24), cv2.FONT_HERSHEY_SIMPLEX, 0.6,
                        (0, 0, 255), 2)
            tiles.append(tile)
        rows.append(np.concatenate(tiles, axis=1))
    width = max(r.shape[1] for r in rows)
    sheet = np.concatenate([np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0)), constant_values=255) for r in rows])
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), sheet)


def side_by_side(results: dict) -> list[str]:
    """One markdown table of the motion's scores, a row per case and a column group per landmark model: PA-MPJPE,
    its ratio to that model's BlazePose, WA-MPJPE, the share of joint-frames turning > 45°, identities."""
    models = list(results)
    cases = list(dict.fromkeys(case for rows in results.values() for case in rows))
    head = "| case | " + " | ".join(f"{m}: PA mm (x BlazePose) | WA mm | >45° | ids" for m in models) + " |"
    lines = [head, "|---|" + "---|---|---|---|" * len(models)]
    for case in cases:
        cells = []
        for model in models:
            rows = results[model].get(case)
            if rows is None:
                cells.append(" | | | ")
                continue
            motion, blazepose = rows["motion"], rows["blazepose"]
            cells.append(f"{motion['pa_mpjpe_mm']:.1f} ({motion['pa_mpjpe_mm'] / blazepose['pa_mpjpe_mm']:.2f}) | "
                         f"{motion['wa_mpjpe_mm']:.0f} | {100 * motion['rotation_change_over_45deg']:.1f}% | "
                         f"{rows['identities']}")
        lines.append(f"| {case} | " + " | ".join(cells) + " |")
    return lines


def main():
    from jaxmocap.detect.models import LANDMARK_MODELS

    parser = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("bench/results"))
    parser.add_argument("--quick", action="store_true", help="the bundled view only")
    parser.add_argument("--views", nargs="*", choices=sorted(VIEWS), default=sorted(VIEWS))
    parser.add_argument("--variants", nargs="*", choices=(*VARIANTS, "all"), default=[],
                        help="each view also so transformed (all: every variant)")
    parser.add_argument("--landmarks", nargs="+", choices=tuple(LANDMARK_MODELS), default=["heavy"],
                        help="BlazePose landmark models, each case run with each (default: heavy, the run's)")
    parser.add_argument("--sheet", type=Path, default=None, help="contact sheet PNG of the worst frames")
    parser.add_argument("--chunk", type=int, default=None, help="frames per chunk of each run (default: the run's)")
    args = parser.parse_args()
    import tempfile

    views = {v: VIEWS[v] for v in (["cam01"] if args.quick else args.views)}
    variants = VARIANTS if "all" in args.variants else tuple(args.variants)
    reference = load_reference()
    results = {model: {} for model in args.landmarks}
    motions, per_frame, person_x = {}, {}, {}
    statics = {model: {} for model in args.landmarks}
    sizes = {view: video_size(video) for view, video in views.items()}
    for view, video in views.items():
        for kind in (None, *variants):
            name = view if kind is None else f"{view}/{kind}"
            for model in args.landmarks:
                begin = time.perf_counter()
                with tempfile.TemporaryDirectory() as work:
                    work = Path(work)
                    source = video if kind is None else write_variant(video, kind, work / "variant.mp4",
                                                                      person_x[view])
                    stages = run_stages(source, work / "run", landmarks=model, chunk_size=args.chunk)
                    held = run_stages(source, work / "held", landmarks=model, chunk_size=args.chunk,
                                      camera="static") if kind == "pan" else None
                results[model][name] = report_view(name, stages, variant_reference(reference, kind),
                                                   variant_up(room_up(view), kind, sizes[view])) | {
                    "seconds": time.perf_counter() - begin}
                if held is not None:  # the panning camera's world motion against the static view's
                    results[model][name]["panning"] = panning_scores(stages.motion, held.motion, statics[model][view])
                if kind is None:
                    statics[model][view] = stages.motion
                print(f"{name} [{model}]: {time.perf_counter() - begin:.0f} s", flush=True)
                if kind is None and model == args.landmarks[0]:
                    motions[name] = stages.motion
                    per_frame[name] = results[model][name]["motion"]["per_frame_pa_mpjpe_mm"]
                    person_x[view] = float(np.median(stages.motion["camera_trans"][stages.motion["valid"], 0]))

    print(f"\naccuracy on real footage (Pose2Sim single-person take), {platform.machine()}")
    print(f"{'view':>14} {'model':>6} {'stage':>10} {'frames':>6} {'PA-MPJPE mm':>11} {'WA-MPJPE':>8} {'flex MAE':>9} "
          f"{'accel':>7} {'2D med px':>9} {'>40px':>6} {'valid':>6} {'rot med':>8} {'>45deg':>7} "
          f"{'fingers back':>12} {'turns>45':>8} {'ids':>3} {'floor':>6} {'contact':>7}")
    for model, cases in results.items():
        for name, rows in cases.items():
            for stage in ("blazepose", "ik", "motion"):
                r = rows[stage]
                extra = (f"{r['reprojection_median_px']:>9.1f} {100 * r['reprojection_over_40px']:>5.0f}% "
                         f"{100 * r['valid_share']:>5.0f}%" if "valid_share" in r else f"{'':>9} {'':>6} {'':>6}")
                coherence = (f"{r['rotation_change_median_deg']:>7.1f}° "
                             f"{100 * r['rotation_change_over_45deg']:>6.1f}% {100 * r['fingers_backwards']:>11.1f}% "
                             f"{100 * r['global_turn_over_45deg']:>7.1f}%" if "rotation_change_median_deg" in r else "")
                if stage == "motion":
                    floor = "-" if r["floor_angle_deg"] is None else f"{r['floor_angle_deg']:.1f}°"
                    contact = "-" if r["contact_share"] is None else f"{100 * r['contact_share']:.0f}%"
                    coherence += f" {rows['identities']:>3} {floor:>6} {contact:>7}"
                print(f"{name:>14} {model:>6} {stage:>10} {r['frames_scored']:>6} {r['pa_mpjpe_mm']:>11.1f} "
                      f"{r['wa_mpjpe_mm']:>8.0f} {r['flexion_mae_deg']:>8.1f}° {r['accel_error_mm']:>7.1f} {extra} "
                      f"{coherence}")
    print(f"\nworld frame: {'case':>14} {'model':>6} {'floor':>6} {'world WA':>8} {'still ankle mm':>14} "
          f"{'ref mm':>6} {'ratio':>5} {'contact':>7} {'on floor':>8} {'lowest sole':>11}")
    for model, cases in results.items():
        for name, rows in cases.items():
            r = rows["motion"]
            if r.get("world_wa_mpjpe_mm") is None:
                continue
            floor = f"{r['floor_angle_deg']:.1f}°"
            on_floor = "-" if r["contact_on_floor"] is None else f"{100 * r['contact_on_floor']:.0f}%"
            print(f"{'':>12} {name:>14} {model:>6} {floor:>6} {r['world_wa_mpjpe_mm']:>8.0f} "
                  f"{r['still_ankle_mm']:>14.1f} {r['reference_still_mm']:>6.1f} {r['sliding_ratio']:>5.2f} "
                  f"{100 * r['contact_share']:>6.0f}% {on_floor:>8} {r['lowest_sole_cm']:>9.1f}cm")
    print(f"\npanning camera: {'case':>14} {'model':>6} {'turned':>7} {'world vs static view mm':>23} "
          f"{'held still: mm':>14}")
    for model, cases in results.items():
        for name, rows in cases.items():
            if "panning" in rows:
                r = rows["panning"]
                print(f"{'':>15} {name:>14} {model:>6} {r['turned_deg']:>6.1f}° {r['world_vs_static_mm']:>23.0f} "
                      f"{r['held_still_vs_static_mm']:>14.0f}")
    print()
    print("\n".join(side_by_side(results)))
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "accuracy.json").write_text(json.dumps(dict(benchmark="accuracy", machine=platform.machine(),
                                                            landmarks=results), indent=1))
    print(f"wrote {args.out / 'accuracy.json'}")
    if args.sheet:
        contact_sheet(args.sheet, views, motions, per_frame)
        print(f"wrote {args.sheet}")


if __name__ == "__main__":
    from jaxmocap.xla_options import configure_process

    configure_process()  # a command of the project: its process's settings before JAX starts
    main()
