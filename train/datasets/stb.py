"""Stereo Hand Pose Tracking Benchmark (Zhang et al. 2017), SK (RealSense colour) images, layout of its release
(github.com/zhjwustc/icip17_stereo_hand_pose_dataset) as loaders read it (e.g. github.com/lixiny/bihand):

    ROOT/images/SEQ/SK_color_%d.png         640x480, 1500 frames per sequence
    ROOT/labels/SEQ_SK.mat                  handPara (3, 21, 1500): millimetres, the SK depth camera's frame

SEQ in B1..B6 x {Counting, Random}; the standard split trains on B2-B6 and tests on B1. Joint order: palm centre,
then pinky, ring, middle, index, thumb, each from base to tip. Labels move to the colour camera with the SK
extrinsics (colour = (depth - t) R, R = Rodrigues(r)) and project with the SK colour intrinsics. The palm centre
becomes a wrist as bihand does: wrist = middle MCP + 2.2 (palm - middle MCP). Left hands only.
"""

from pathlib import Path

import cv2
import numpy as np
import scipy.io

from train.datasets.hand_joints import (
    MIDDLE_MCP,
    OPENPOSE_FROM_STB,
    WRIST,
    HandSamples,
    check_split,
    checked_array,
    hand_labels,
    hand_samples,
    project,
    require_file,
)

SEQUENCES = {
    "train": tuple(f"B{i}{kind}" for i in range(2, 7) for kind in ("Counting", "Random")),
    "test": ("B1Counting", "B1Random"),
}
SK_COLOR_CAMERA = np.array([[607.92271, 0.0, 314.78337], [0.0, 607.88192, 236.42484], [0.0, 0.0, 1.0]])
SK_ROTVEC = np.array([0.00531, -0.01196, 0.00301])
SK_TRANSLATION_MM = np.array([-24.0381, -0.4563, -1.2326])
PALM_TO_WRIST = 2.2


def joints_color_frame(hand_para: np.ndarray) -> np.ndarray:
    """`handPara` (3, 21, F) in millimetres, depth frame, STB order -> (F, 21, 3) metres, colour frame, OpenPose
    order, with the wrist in place of the palm centre."""
    depth_mm = np.transpose(hand_para, (2, 1, 0))
    color = ((depth_mm - SK_TRANSLATION_MM) @ cv2.Rodrigues(SK_ROTVEC)[0] / 1000.0)[:, OPENPOSE_FROM_STB]
    middle = color[:, MIDDLE_MCP]
    color[:, WRIST] = middle + PALM_TO_WRIST * (color[:, WRIST] - middle)
    return color


def _load_hand_para(path: Path) -> np.ndarray:
    require_file(path, "a MAT file with handPara (3, 21, frames) in millimetres")
    try:
        mat = scipy.io.loadmat(path)
    except (ValueError, OSError, TypeError) as error:
        raise ValueError(f"{path}: corrupt MAT file ({error})") from None
    if "handPara" not in mat:
        raise ValueError(f"{path}: missing variable 'handPara'")
    return checked_array(mat["handPara"], (3, 21, -1), path, "handPara")


def read(root: Path, split: str) -> HandSamples:
    """STB's SK colour images: `train` (B2-B6) or `test` (B1)."""
    check_split("STB", split, SEQUENCES)
    root = Path(root)
    paths, joints = [], []
    for seq in SEQUENCES[split]:
        xyz = joints_color_frame(_load_hand_para(root / "labels" / f"{seq}_SK.mat"))
        paths += [root / "images" / seq / f"SK_color_{i}.png" for i in range(len(xyz))]
        joints.append(xyz)
    joints_3d = np.concatenate(joints)
    labels = hand_labels(np.stack([project(j, SK_COLOR_CAMERA) for j in joints_3d]), joints_3d=joints_3d, is_left=True)
    return hand_samples(paths, labels)
