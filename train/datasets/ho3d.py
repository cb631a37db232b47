"""HO-3D v2/v3 (Hampali et al. 2020), layout of the official scripts (github.com/shreyashampali/ho3d):

    ROOT/train.txt, ROOT/evaluation.txt      one `SEQ/FRAME` per line
    ROOT/{train,evaluation}/SEQ/rgb/FRAME.png (v2) or .jpg (v3)
    ROOT/{train,evaluation}/SEQ/meta/FRAME.pkl, a dict:
        train:       handJoints3D (21,3) MANO order + tips, metres; camMat (3,3); handPose (48,) MANO axis-angle,
                     absolute (flat_hand_mean=True); handBeta (10,); handTrans (3,). None where a frame has no labels.
        evaluation:  handJoints3D (3,) the wrist only; camMat; handBoundingBox (4,) x0, y0, x1, y1.

3D is in OpenGL's camera frame (y up, z backwards): x_cv = diag(1, -1, -1) x_gl, and the wrist rotation likewise
R_cv = diag(1, -1, -1) R_gl. Right hands only. MANO's finger order is SMPL-X's.
"""

from pathlib import Path

import cv2
import numpy as np

from train.datasets.hand_joints import (
    OPENPOSE_FROM_MANO,
    WRIST,
    HandSamples,
    check_split,
    checked_array,
    hand_labels,
    hand_samples,
    load_pickled_dict,
    project,
    require_file,
)

SET_NAMES = {"train": "train", "test": "evaluation"}
OPENGL_TO_OPENCV = np.diag([1.0, -1.0, -1.0])


def _frame_ids(root: Path, set_name: str) -> list[str]:
    path = require_file(root / f"{set_name}.txt", "one SEQ/FRAME per line")
    ids = [line.strip() for line in path.read_text().splitlines() if line.strip()]
    bad = [i for i in ids if len(i.split("/")) != 2]
    if bad:
        raise ValueError(f"{path}: line {bad[0]!r} is not SEQ/FRAME")
    return ids


def _field(meta: dict, key: str, shape: tuple[int, ...], path: Path) -> np.ndarray:
    if key not in meta:
        raise ValueError(f"{path}: missing key {key!r}")
    return checked_array(meta[key], shape, path, key)


def _image_path(seq_dir: Path, frame: str, suffixes: dict[Path, str]) -> Path:
    """v2 stores png, v3 jpg: decided once per sequence from its first frame."""
    if seq_dir not in suffixes:
        suffixes[seq_dir] = ".jpg" if (seq_dir / "rgb" / f"{frame}.jpg").is_file() else ".png"
    return seq_dir / "rgb" / f"{frame}{suffixes[seq_dir]}"


def read(root: Path, split: str) -> HandSamples:
    """HO-3D's `train` (fully labelled frames) or `test` (evaluation: wrist and box only) split."""
    check_split("HO-3D", split, SET_NAMES)
    set_name, root = SET_NAMES[split], Path(root)
    paths, joints_2d, joints_3d, boxes, rotvecs, poses, betas = [], [], [], [], [], [], []
    suffixes: dict[Path, str] = {}
    for frame_id in _frame_ids(root, set_name):
        seq, frame = frame_id.split("/")
        seq_dir = root / set_name / seq
        meta_path = seq_dir / "meta" / f"{frame}.pkl"
        meta = load_pickled_dict(meta_path, "a pickled dict of HO-3D labels")
        if meta.get("handJoints3D") is None:
            continue
        camera = _field(meta, "camMat", (3, 3), meta_path)
        if set_name == "train":
            xyz = _field(meta, "handJoints3D", (21, 3), meta_path)[OPENPOSE_FROM_MANO] @ OPENGL_TO_OPENCV
            pose = _field(meta, "handPose", (48,), meta_path)
            wrist_gl = cv2.Rodrigues(pose[:3])[0]
            rotvecs.append(cv2.Rodrigues(OPENGL_TO_OPENCV @ wrist_gl)[0][:, 0])
            poses.append(pose[3:].reshape(15, 3))
            betas.append(_field(meta, "handBeta", (10,), meta_path))
        else:
            xyz = np.full((21, 3), np.nan)
            xyz[WRIST] = OPENGL_TO_OPENCV @ _field(meta, "handJoints3D", (3,), meta_path)
            x0, y0, x1, y1 = _field(meta, "handBoundingBox", (4,), meta_path)
            boxes.append([x0, y0, x1 - x0, y1 - y0])
        paths.append(_image_path(seq_dir, frame, suffixes))
        joints_3d.append(xyz)
        joints_2d.append(project(xyz, camera))
    labels = hand_labels(
        np.reshape(joints_2d, (-1, 21, 2)),
        joints_3d=np.reshape(joints_3d, (-1, 21, 3)),
        boxes=np.reshape(boxes, (-1, 4)) if set_name == "evaluation" else None,
        wrist_rotvec=np.reshape(rotvecs, (-1, 3)) if set_name == "train" else None,
        hand_pose=np.reshape(poses, (-1, 15, 3)) if set_name == "train" else None,
        betas=np.reshape(betas, (-1, 10)) if set_name == "train" else None,
        is_left=False,
    )
    return hand_samples(paths, labels)
