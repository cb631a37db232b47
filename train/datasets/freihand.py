"""FreiHAND v2 (Zimmermann et al. 2019), layout of the official toolbox (github.com/lmb-freiburg/freihand):

    ROOT/training/rgb/%08d.jpg       4 x 32560 images: 4 versions (green screen, homogenized, sample, auto) of each
                                     sample; image i has the labels of sample i % 32560
    ROOT/training_xyz.json           per sample 21x3 joints, metres, OpenCV camera frame, OpenPose hand order
    ROOT/training_K.json             per sample 3x3 camera matrix
    ROOT/training_mano.json          per sample [[61]]: MANO pose 48 (global 3 + fingers 45, mean-relative), shape 10,
                                     translation 3
    ROOT/evaluation/rgb/%08d.jpg     3960 images, labels evaluation_{xyz,K,mano}.json likewise (released with v2)

Right hands only. The finger pose is relative to MANO's mean hand (the toolbox poses MANO with use_mean_pose=True),
which needs the licensed model file to become absolute, so `hand_pose` is NaN; the wrist orientation is absolute.
"""

import json
from pathlib import Path

import numpy as np

from train.datasets.hand_joints import (
    HandSamples,
    check_split,
    checked_array,
    hand_labels,
    project,
    require_file,
)

SET_NAMES = {"train": "training", "test": "evaluation"}
VERSIONS = {"training": 4, "evaluation": 1}


def _load_json_list(path: Path, expected: str) -> list:
    require_file(path, expected)
    try:
        values = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: corrupt JSON ({error}); expected {expected}") from None
    if not isinstance(values, list):
        raise ValueError(f"{path}: expected {expected}, got {type(values).__name__}")
    return values


def read(root: Path, split: str) -> HandSamples:
    """FreiHAND's `train` (training, all 4 versions) or `test` (evaluation) split."""
    check_split("FreiHAND", split, SET_NAMES)
    set_name = SET_NAMES[split]
    root = Path(root)
    xyz_path, k_path, mano_path = (root / f"{set_name}_{kind}.json" for kind in ("xyz", "K", "mano"))
    xyz = checked_array(_load_json_list(xyz_path, "a list of 21x3 joints"), (-1, 21, 3), xyz_path, "joints")
    camera = checked_array(_load_json_list(k_path, "a list of 3x3 camera matrices"), (-1, 3, 3), k_path, "K")
    mano = checked_array(
        _load_json_list(mano_path, "a list of [[61]] MANO parameters"), (-1, 1, 61), mano_path, "MANO parameters"
    )[:, 0]
    if not len(xyz) == len(camera) == len(mano):
        raise ValueError(
            f"{root}: {xyz_path.name}, {k_path.name} and {mano_path.name} hold {len(xyz)}, "
            f"{len(camera)} and {len(mano)} samples; expected equal counts"
        )
    labels = hand_labels(
        np.stack([project(j, k) for j, k in zip(xyz, camera)]) if len(xyz) else np.zeros((0, 21, 2)),
        joints_3d=xyz,
        wrist_rotvec=mano[:, :3],
        betas=mano[:, 48:58],
        is_left=False,
    )
    count = VERSIONS[set_name] * len(xyz)
    paths = tuple(root / set_name / "rgb" / f"{i:08d}.jpg" for i in range(count))
    return HandSamples(paths, labels, np.arange(count) % max(len(xyz), 1))
