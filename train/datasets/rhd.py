"""Rendered Hand Pose Dataset (Zimmermann & Brox 2017), layout of its release (lmb-freiburg, RHD_published_v2):

    ROOT/{training,evaluation}/color/%05d.png            320x320 renderings
    ROOT/{training,evaluation}/anno_{training,evaluation}.pickle
        {sample id: {'uv_vis': (42,3) pixels + visible flag, 'xyz': (42,3) metres camera frame, 'K': (3,3)}}

Keypoints 0-20 are the left hand, 21-41 the right, each in RHD's order (wrist, then every finger from tip to base).
One hand per image: the one with more visible keypoints (ties go to the right hand), so heavily occluded second hands
do not become samples. All 21 2D keypoints are labels (exact projections of the 3D ones, occluded or not), and the
box covers them all.
"""

from pathlib import Path

import numpy as np

from train.datasets.hand_joints import (
    OPENPOSE_FROM_RHD,
    HandSamples,
    check_split,
    checked_array,
    hand_labels,
    hand_samples,
    load_pickled_dict,
)

SET_NAMES = {"train": "training", "test": "evaluation"}
EXPECTED = "a pickled dict {sample id: {'uv_vis', 'xyz', 'K'}}"


def read(root: Path, split: str) -> HandSamples:
    """RHD's `train` (training) or `test` (evaluation) split, one hand per image."""
    check_split("RHD", split, SET_NAMES)
    set_name, root = SET_NAMES[split], Path(root)
    path = root / set_name / f"anno_{set_name}.pickle"
    paths, joints_2d, joints_3d, is_left = [], [], [], []
    for sample_id, annotation in sorted(load_pickled_dict(path, EXPECTED).items()):
        source = f"{path} sample {sample_id}"
        if not isinstance(annotation, dict) or not {"uv_vis", "xyz"} <= annotation.keys():
            raise ValueError(f"{source}: expected a dict with 'uv_vis' (42,3) and 'xyz' (42,3)")
        uv_vis = checked_array(annotation["uv_vis"], (42, 3), source, "uv_vis").reshape(2, 21, 3)
        xyz = checked_array(annotation["xyz"], (42, 3), source, "xyz").reshape(2, 21, 3)
        visible = uv_vis[:, :, 2] > 0.5
        hand = int(visible[1].sum() >= visible[0].sum())  # 0 left, 1 right
        uv = uv_vis[hand, OPENPOSE_FROM_RHD, :2]
        paths.append(root / set_name / "color" / f"{sample_id:05d}.png")
        joints_2d.append(uv)
        joints_3d.append(xyz[hand, OPENPOSE_FROM_RHD])
        is_left.append(hand == 0)
    labels = hand_labels(
        np.reshape(joints_2d, (-1, 21, 2)),
        joints_3d=np.reshape(joints_3d, (-1, 21, 3)),
        is_left=np.array(is_left, bool),
    )
    return hand_samples(paths, labels)
