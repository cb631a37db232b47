"""What a dataset adapter yields (one labelled hand or body in a full image) and what the network is trained on
(a fixed-size augmented crop with its labels in crop coordinates).

Frames: 3D labels are in the camera frame, metres, x right, y down, z forward (OpenCV); a SMPL-X global
orientation maps the model's y-up frame into it (as in motion.npz). Unknown labels are NaN in a sample and
masked (zeros + mask False) in an example. Hand joints are in OpenPose hand order (21); body joints BODY_25.
"""

from pathlib import Path
from typing import NamedTuple

import cv2
import numpy as np
from jaxtyping import Bool, Float, UInt8

NUM_HAND_JOINTS, NUM_BODY_JOINTS = 21, 25


class HandSample(NamedTuple):
    """One hand in one image."""

    image: UInt8[np.ndarray, "H W 3"]  # BGR, as cv2.imread gives it
    box: Float[np.ndarray, "4"]  # x, y, w, h of the hand in pixels
    joints_2d: Float[np.ndarray, "21 2"]  # pixels, OpenPose hand order; NaN where not labelled
    joints_3d: Float[np.ndarray, "21 3"]  # metres, camera frame, OpenPose hand order; NaN where unknown
    wrist_rotvec: Float[np.ndarray, "3"]  # global wrist orientation of SMPL-X's hand in the camera frame
    hand_pose: Float[np.ndarray, "15 3"]  # absolute axis-angle, SMPL-X finger order, the hand's own side
    betas: Float[np.ndarray, "10"]
    is_left: bool


class BodySample(NamedTuple):
    """One person in one image."""

    image: UInt8[np.ndarray, "H W 3"]  # BGR
    box: Float[np.ndarray, "4"]  # x, y, w, h of the person in pixels
    joints_2d: Float[np.ndarray, "25 2"]  # pixels, BODY_25; NaN where not labelled
    joints_3d: Float[np.ndarray, "25 3"]  # metres, camera frame, BODY_25; NaN where unknown
    global_orient: Float[np.ndarray, "3"]  # SMPL-X global orientation in the camera frame
    body_pose: Float[np.ndarray, "21 3"]  # SMPL-X body joints 1..21 (= SMPL's 1..21)
    betas: Float[np.ndarray, "10"]


class HandExample(NamedTuple):
    """A network-ready right hand (left ones mirrored): fixed shapes, stacked into batches."""

    image: Float[np.ndarray, "S S 3"]  # BGR, (x/255 - 0.5)/0.5 as FrankMocap's hand network takes it
    joints_2d: Float[np.ndarray, "21 2"]  # crop coordinates in [-1, 1]: pixel / (S/2) - 1
    joints_2d_mask: Bool[np.ndarray, "21"]
    joints_3d: Float[np.ndarray, "21 3"]  # metres, camera frame after augmentation (in-plane rotation applied)
    joints_3d_mask: Bool[np.ndarray, ""]
    pose: Float[np.ndarray, "16 3"]  # wrist global + 15 absolute finger axis-angles, as a right hand
    pose_mask: Bool[np.ndarray, ""]
    betas: Float[np.ndarray, "10"]
    betas_mask: Bool[np.ndarray, ""]


class BodyExample(NamedTuple):
    """A network-ready person crop."""

    image: Float[np.ndarray, "S S 3"]  # RGB, ImageNet mean/std as the body network takes it
    joints_2d: Float[np.ndarray, "25 2"]  # crop coordinates in [-1, 1]
    joints_2d_mask: Bool[np.ndarray, "25"]
    joints_3d: Float[np.ndarray, "25 3"]  # metres, camera frame after augmentation
    joints_3d_mask: Bool[np.ndarray, ""]
    pose: Float[np.ndarray, "22 3"]  # global orientation + 21 body joints, axis-angle
    pose_mask: Bool[np.ndarray, ""]
    betas: Float[np.ndarray, "10"]
    betas_mask: Bool[np.ndarray, ""]


def read_colour_image(path: Path) -> UInt8[np.ndarray, "H W 3"]:
    """A sample's image, BGR as cv2.imread gives it; FileNotFoundError naming the file if it cannot be read."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        raise FileNotFoundError(f"{path}: missing or unreadable image (expected a colour image)")
    return image


def box_of_joints(joints_2d: Float[np.ndarray, "J 2"], margin: float = 0.0) -> Float[np.ndarray, "4"]:
    """``x, y, w, h`` of the tight box of the labelled (finite) 2D joints, each side grown by ``margin`` times its
    longer side; NaN if none is labelled."""
    labelled = joints_2d[np.isfinite(joints_2d).all(axis=-1)]
    if len(labelled) == 0:
        return np.full(4, np.nan, np.float32)
    low, high = labelled.min(axis=0), labelled.max(axis=0)
    grow = margin * (high - low).max()
    return np.concatenate([low - grow, high - low + 2 * grow]).astype(np.float32)
