"""MPII+NZSL hand keypoints (Simon et al. 2017, CMU Panoptic "hand_labels"), layout of its release:

    ROOT/hand_labels/manual_{train,test}/NAME.jpg       one image per hand
    ROOT/hand_labels/manual_{train,test}/NAME.json      {"hand_pts": 21 x [x, y, flag] pixels, OpenPose order,
                                                        flag 1 = annotated; "is_left": 0/1; ...}

2D only: 3D, pose and shape are NaN, as are points whose flag is not 1.
"""

import json
from pathlib import Path

import numpy as np

from train.datasets.hand_joints import HandSamples, check_split, checked_array, hand_labels, hand_samples

FOLDERS = {"train": "manual_train", "test": "manual_test"}


def _load_label(path: Path) -> tuple[np.ndarray, bool]:
    try:
        label = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: corrupt JSON ({error})") from None
    if not isinstance(label, dict) or "hand_pts" not in label or "is_left" not in label:
        raise ValueError(f"{path}: expected a dict with 'hand_pts' (21 x [x, y, flag]) and 'is_left'")
    points = checked_array(label["hand_pts"], (21, 3), path, "hand_pts")
    if not (points[:, 2] == 1).any():
        raise ValueError(f"{path}: no point of hand_pts is annotated (flag 1)")
    return np.where(points[:, 2:] == 1, points[:, :2], np.nan), bool(label["is_left"])


def read(root: Path, split: str) -> HandSamples:
    """MPII+NZSL's `train` (manual_train) or `test` (manual_test) hands."""
    check_split("MPII+NZSL", split, FOLDERS)
    folder = Path(root) / "hand_labels" / FOLDERS[split]
    if not folder.is_dir():
        raise FileNotFoundError(f"{folder}: missing; expected a folder of NAME.jpg + NAME.json hand labels")
    label_paths = sorted(folder.glob("*.json"))
    if not label_paths:
        raise FileNotFoundError(f"{folder}: no NAME.json hand labels")
    labels = [_load_label(path) for path in label_paths]
    hands = hand_labels(
        np.reshape([points for points, _ in labels], (-1, 21, 2)),
        is_left=np.array([is_left for _, is_left in labels], bool),
    )
    return hand_samples([path.with_suffix(".jpg") for path in label_paths], hands)
