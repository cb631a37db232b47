"""A motion (``motion.npz`` arrays) as a skeletal animation in a y-up world frame, shared by the exporters.

``frame="world"`` (the default, where the motion has one: its world keys, docs/formats.md): the motion's own world
frame, y up, the floor y = 0, the body where it stood and walked. Else (``frame="camera"``, or a motion without
world keys) the image's camera frame (x right, y down, z away from the camera) turned by pi about x (x right, y up,
z towards the camera), the frame glTF and Blender's importers expect: a motion fitted through a pinhole camera
placed by ``transl``, a weak-perspective one at depth ``focal / camera_scale`` for an assumed focal length in
pixels (default: the image diagonal, a ~53 degree field of view).
"""

from dataclasses import dataclass

import jax
import numpy as np

import smplx_jax
from jaxmocap.motion import lens, motion_params
from smplx_jax import SIDES, constants
from smplx_jax.rotations import rotvec_to_rotmat

CAMERA_TO_WORLD = np.diag([1.0, -1.0, -1.0])
FRAMES = ("world", "camera")

# Where the bone of each joint without children ends (its BVH End Site): the mean of these of the 127 joints
# (vertex joints and face landmarks) on the rest mesh. Feet reach the toe tips, the jaw the middle of the lower
# lip (landmark 40: 68-point landmark 57), the eyes their eye vertex in front, the last finger joints the tips.
_LOWER_LIP = constants.NUM_JOINTS + len(constants.VERTEX_JOINT_NAMES) + 40
_VERTEX_JOINT = {name: constants.NUM_JOINTS + k for k, name in enumerate(constants.VERTEX_JOINT_NAMES)}
LEAF_TIPS = {
    "jaw": (_LOWER_LIP,),
    **{f"{side}_foot": (_VERTEX_JOINT[f"{side}_big_toe"], _VERTEX_JOINT[f"{side}_small_toe"])
       for side in SIDES},
    **{f"{side}_eye": (_VERTEX_JOINT[f"{side}_eye_vertex"],) for side in SIDES},
    **{f"{side}_{finger}3": (_VERTEX_JOINT[f"{side}_{finger}_tip"],)
       for side in SIDES for finger in ("thumb", "index", "middle", "ring", "pinky")},
}
MIN_BONE_LENGTH = 0.005  # metres; a leaf whose tip is nearer than this continues its parent's bone instead


@dataclass(frozen=True)
class Animation:
    """``T`` frames of a skeleton of ``J`` joints (SMPL-X's 55, or a hand's 16): local rotations (the root's
    relative to the world), the root's world position, and the rest skeleton of the motion's mean shape."""

    names: tuple[str, ...]
    parents: tuple[int, ...]
    rest_joints: np.ndarray  # (J, 3) rest-pose joint positions, metres
    local_rotmats: np.ndarray  # (T, J, 3, 3)
    root_positions: np.ndarray  # (T, 3) world position of joint 0
    betas: np.ndarray  # (B,) the mean shape over valid frames
    fps: float
    end_sites: np.ndarray  # (J, 3) rest-pose offset from each joint without children to its bone's end; 0 for others


def rest_keypoints(model: smplx_jax.BodyModel, betas: np.ndarray) -> np.ndarray:
    """(72, 3) forward's joints 55..126 (21 vertex joints, 51 face landmarks) of a shape in the rest pose."""
    sparse = np.asarray(model.sparse_template_cm, np.float64)
    sparse = sparse + (betas @ np.asarray(model.sparse_shapedirs_cm, np.float64)[: len(betas)]).reshape(3, -1)
    vertex_joints = sparse[:, np.asarray(model.vertex_joint_slots)].T
    landmarks = np.einsum("lk,clk->lc", np.asarray(model.landmark_bary, np.float64),
                          sparse[:, np.asarray(model.landmark_slots)])
    return np.concatenate([vertex_joints, landmarks])


def end_sites(model: smplx_jax.BodyModel, betas: np.ndarray, rest_joints: np.ndarray) -> np.ndarray:
    """(55, 3) offsets from each joint without children to where its bone ends (`LEAF_TIPS` on the rest mesh),
    so that no bone of an exported skeleton has zero length; zero for joints with children."""
    points = np.concatenate([rest_joints, rest_keypoints(model, betas)])
    parents = model.parents
    offsets = np.zeros_like(rest_joints)
    for j, name in enumerate(constants.JOINT_NAMES):
        if j in parents:
            continue
        offsets[j] = points[list(LEAF_TIPS[name])].mean(axis=0) - rest_joints[j] if name in LEAF_TIPS else 0.0
        if np.linalg.norm(offsets[j]) < MIN_BONE_LENGTH:  # a model file whose tip is missing: go on straight
            bone = rest_joints[j] - rest_joints[parents[j]]
            offsets[j] = bone * max(0.5, MIN_BONE_LENGTH / max(float(np.linalg.norm(bone)), 1e-9))
    return offsets


def held_frames(valid: np.ndarray) -> np.ndarray:
    """For each frame, the index of the nearest earlier valid frame (the first valid one before any)."""
    if not valid.any():
        raise ValueError("the motion has no valid frame to export")
    index = np.where(valid, np.arange(len(valid)), -1)
    index = np.maximum.accumulate(index)
    return np.where(index < 0, np.argmax(valid), index)


def weak_perspective_origin(camera_scale, camera_trans, image_size, focal_px: float | None = None) -> np.ndarray:
    """(T, 3) where a weak-perspective camera (``camera_scale (T,)``, ``camera_trans (T, 2)``) puts the model's
    origin in the camera frame: at depth ``focal / camera_scale``, in front of its pixel ``camera_trans``."""
    width, height = np.asarray(image_size, np.float64)
    focal = float(np.hypot(width, height)) if focal_px is None else focal_px
    scale = np.asarray(camera_scale, np.float64)
    return np.concatenate([(np.asarray(camera_trans, np.float64) - [width / 2, height / 2]) / scale[:, None],
                           (focal / scale)[:, None]], axis=1)


def animation(model: smplx_jax.BodyModel, motion, focal_px: float | None = None, frame: str = "world") -> Animation:
    """The animation of a motion in its world frame or the camera's (module docstring); invalid frames hold the
    previous valid frame's pose."""
    if frame not in FRAMES:
        raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
    valid = np.asarray(motion["valid"], bool)
    held = held_frames(valid)
    betas = np.asarray(motion["betas"], np.float64)[valid].mean(axis=0)
    num = betas.shape[0]
    rest_joints = np.asarray(model.joint_template, np.float64) + np.asarray(model.joint_shapedirs)[..., :num] @ betas
    full_pose = jax.vmap(smplx_jax.SMPLXParams.full_pose)(motion_params(motion, model.num_expression, held))
    local = np.asarray(rotvec_to_rotmat(full_pose), np.float64)
    if frame == "world" and "world_transl" in motion:
        local[:, 0] = np.asarray(rotvec_to_rotmat(np.asarray(motion["world_global_orient"], np.float64)[held]))
        root = np.asarray(motion["world_transl"], np.float64)[held] + rest_joints[0]
    else:
        local[:, 0] = CAMERA_TO_WORLD @ local[:, 0]
        origin = weak_perspective_origin(np.asarray(motion["camera_scale"])[held],
                                         np.asarray(motion["camera_trans"])[held], motion["image_size"],
                                         focal_px) if lens(motion)[0] is None else 0.0
        root = (origin + np.asarray(motion["transl"], np.float64)[held] + rest_joints[0]) @ CAMERA_TO_WORLD.T
    return Animation(
        names=constants.JOINT_NAMES, parents=model.parents, rest_joints=rest_joints, local_rotmats=local,
        root_positions=root, betas=betas, fps=float(motion["fps"]), end_sites=end_sites(model, betas, rest_joints))


def global_transforms(anim: Animation) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (T, J, 3, 3) and positions (T, J, 3) of every joint."""
    rot = np.zeros_like(anim.local_rotmats)
    pos = np.zeros(anim.local_rotmats.shape[:2] + (3,))
    rot[:, 0], pos[:, 0] = anim.local_rotmats[:, 0], anim.root_positions
    for j in range(1, len(anim.parents)):
        p = anim.parents[j]
        rot[:, j] = rot[:, p] @ anim.local_rotmats[:, j]
        pos[:, j] = pos[:, p] + np.einsum("tij,j->ti", rot[:, p], anim.rest_joints[j] - anim.rest_joints[p])
    return rot, pos
