"""Body joint sets of the public datasets mapped to OpenPose BODY_25, SPIN's 24-joint label layout, person boxes,
and the lazily loaded sequence of `BodySample` the body dataset adapters return.

A dataset joint maps to a BODY_25 joint only where both name the same anatomical point; the MPII/H36M pelvis is
taken as BODY_25's MidHip and the thorax as its Neck (OpenPose defines both as the midpoints of the hips and of the
shoulders). Every other BODY_25 joint is NaN (unknown) for that dataset.
"""

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
from jaxtyping import Bool, Float, Int

from train.datasets.sample import NUM_BODY_JOINTS, BodySample, read_colour_image

BODY_25_NAMES = (
    "nose", "neck", "right_shoulder", "right_elbow", "right_wrist", "left_shoulder", "left_elbow", "left_wrist",
    "mid_hip", "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee", "left_ankle", "right_eye",
    "left_eye", "right_ear", "left_ear", "left_big_toe", "left_small_toe", "left_heel", "right_big_toe",
    "right_small_toe", "right_heel",
)
COCO_17_NAMES = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder", "left_elbow",
    "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle",
    "right_ankle",
)
MPII_16_NAMES = (
    "right_ankle", "right_knee", "right_hip", "left_hip", "left_knee", "left_ankle", "pelvis", "thorax",
    "upper_neck", "head_top", "right_wrist", "right_elbow", "right_shoulder", "left_shoulder", "left_elbow",
    "left_wrist",
)
# Human3.6M's 17-joint subset in its usual order (raw joints 0,1,2,3,6,7,8,12,13,14,15,17,18,19,25,26,27).
H36M_17_NAMES = (
    "pelvis", "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee", "left_ankle", "spine", "thorax",
    "neck_nose", "head", "left_shoulder", "left_elbow", "left_wrist", "right_shoulder", "right_elbow", "right_wrist",
)
_SAME_POINT = {"pelvis": "mid_hip", "thorax": "neck"}


def _to_body_25_index(names: tuple[str, ...]) -> Int[np.ndarray, "25"]:
    canonical = [_SAME_POINT.get(name, name) for name in names]
    return np.array([canonical.index(name) if name in canonical else -1 for name in BODY_25_NAMES])


# For each BODY_25 joint, the index of the same joint in the dataset's order, or -1 where the dataset has none.
COCO_17_TO_BODY_25 = _to_body_25_index(COCO_17_NAMES)
MPII_16_TO_BODY_25 = _to_body_25_index(MPII_16_NAMES)
H36M_17_TO_BODY_25 = _to_body_25_index(H36M_17_NAMES)

# SPIN's labels (nkolot/SPIN constants.py, datasets/preprocess/*.py; EFT's json reuses them) keep 2D `part` (24,3)
# and 3D `S` (24,4) in 24 slots shared by all datasets; these are the slots of each dataset's joints, in its order.
# The H36M thorax sits in SPIN's "Neck (LSP)" slot 12.
SPIN_24_SLOTS_OF_COCO_17 = np.array([19, 20, 21, 22, 23, 9, 8, 10, 7, 11, 6, 3, 2, 4, 1, 5, 0])
SPIN_24_SLOTS_OF_MPII_16 = np.array([0, 1, 2, 3, 4, 5, 14, 15, 12, 13, 6, 7, 8, 9, 10, 11])
SPIN_24_SLOTS_OF_H36M_17 = np.array([14, 2, 1, 0, 3, 4, 5, 16, 12, 17, 18, 9, 10, 11, 8, 7, 6])


def to_body_25(
    points: Float[np.ndarray, "*batch J D"], valid: Bool[np.ndarray, "*batch J"], index: Int[np.ndarray, "25"]
) -> Float[np.ndarray, "*batch 25 D"]:
    """Dataset joints to BODY_25 through `index` (one of the `*_TO_BODY_25`); NaN where unmapped or not valid."""
    picked = np.take(points, np.maximum(index, 0), axis=-2).astype(np.float32)
    known = np.take(valid, np.maximum(index, 0), axis=-1) & (index >= 0)
    return np.where(known[..., None], picked, np.float32(np.nan))


def spin_to_body_25(
    labels: Float[np.ndarray, "*batch 24 C"], slots: Int[np.ndarray, "J"], index: Int[np.ndarray, "25"]
) -> Float[np.ndarray, "*batch 25 C-1"]:
    """SPIN-layout labels (coordinates + confidence last) of a dataset to BODY_25; confidence 0 means unlabelled."""
    joints = np.take(labels, slots, axis=-2)
    return to_body_25(joints[..., :-1], joints[..., -1] > 0, index)


def fill_from_openpose(
    joints_2d: Float[np.ndarray, "*batch 25 2"],
    openpose: Float[np.ndarray, "*batch 25 3"],
    index: Int[np.ndarray, "25"],
) -> Float[np.ndarray, "*batch 25 2"]:
    """BODY_25 joints the dataset's skeleton lacks (index -1) taken from SPIN's `openpose` keypoints (confidence > 0).

    Those are OpenPose detections SPIN matched to the person, or for EFT's COCO the COCO-foot annotations (or zeros).
    """
    from_openpose = to_body_25(openpose[..., :2], openpose[..., 2] > 0, np.arange(NUM_BODY_JOINTS))
    return np.where((index < 0)[:, None], from_openpose, joints_2d)


def box_from_center_scale(
    center: Float[np.ndarray, "*batch 2"], scale: Float[np.ndarray, "*batch"], expansion: float
) -> Float[np.ndarray, "*batch 4"]:
    """SPIN's box (a square of side 200·scale around `center`) back to the person's x, y, w, h.

    `expansion` is the factor the dataset's preprocessing multiplied the person's longest side by (SPIN/EFT: COCO 1.2,
    Human3.6M 0.9, MPII 1.0, whose scale is the annotated person height / 200).
    """
    side = 200.0 * np.asarray(scale, np.float32) / expansion
    top_left = np.asarray(center, np.float32) - side[..., None] / 2
    return np.concatenate([top_left, side[..., None], side[..., None]], axis=-1)


class BodyLabels(NamedTuple):
    """The labels of N samples, stacked (the fields of `BodySample` but the image)."""

    box: Float[np.ndarray, "N 4"]
    joints_2d: Float[np.ndarray, "N 25 2"]
    joints_3d: Float[np.ndarray, "N 25 3"]
    global_orient: Float[np.ndarray, "N 3"]
    body_pose: Float[np.ndarray, "N 21 3"]
    betas: Float[np.ndarray, "N 10"]


@dataclass(frozen=True)
class BodySamples(Sequence):  # of BodySample; Sequence[BodySample] would make runtime checkers load one
    """Labels parsed once; each image read when its sample is taken."""

    image_paths: tuple[Path, ...]
    labels: BodyLabels

    def __post_init__(self):
        for name, array in self.labels._asdict().items():
            if len(array) != len(self.image_paths):
                raise ValueError(f"labels.{name} has {len(array)} rows for {len(self.image_paths)} images")

    def __len__(self) -> int:
        return len(self.image_paths)

    def __getitem__(self, index: int) -> BodySample:
        image = read_colour_image(self.image_paths[index])
        return BodySample(image=image, **{name: array[index] for name, array in self.labels._asdict().items()})
