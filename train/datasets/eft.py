"""COCO 2014 and MPII with EFT's pseudo ground truth (facebookresearch/eft, docs/README_dataformat.md).

Layout (EFT's scripts/download_eft.sh writes eft_fit/; the images come from the datasets' own sites):

    COCO_ROOT/eft_fit/COCO2014-All-ver01.json    COCO_ROOT/train2014/<imageName>
    MPII_ROOT/eft_fit/MPII_ver01.json            MPII_ROOT/images/<imageName>

A json file is ``{"ver": ..., "data": [entry, ...]}``, one entry per person: SMPL fitted by EFT in SPIN's camera
frame (x right, y down, z forward; `parm_pose[0]` maps SMPL's y-up frame into it, as SPIN's HMR predicts),
`parm_pose` (24,3,3) rotation matrices, `parm_shape` (10) SMPL betas, `bbox_center` (2) and `bbox_scale` (SPIN's
center/scale box) and `gt_keypoint_2d` (49,3) pixels + confidence in SPIN's order: 25 OpenPose slots (zeros or
COCO-foot annotations for COCO, OpenPose detections for MPII) then SPIN's 24 annotated slots.

Samples: body pose = SMPL joints 1..21 (= SMPL-X's); betas stay SMPL's (not SMPL-X's shape space); 3D joints are
unknown (NaN); 2D joints are the dataset's annotations, with BODY_25 joints the dataset lacks (neck and mid-hip for
COCO, the feet) from the OpenPose slots.
"""

import json
from pathlib import Path

import numpy as np
from jaxtyping import Float, Int

from smplx_jax.rotations import rotmat_to_rotvec
from train.datasets.body_joints import (
    COCO_17_TO_BODY_25,
    MPII_16_TO_BODY_25,
    SPIN_24_SLOTS_OF_COCO_17,
    SPIN_24_SLOTS_OF_MPII_16,
    BodyLabels,
    BodySamples,
    box_from_center_scale,
    fill_from_openpose,
    spin_to_body_25,
)
from train.datasets.sample import NUM_BODY_JOINTS

_ENTRY_SHAPES = {
    "parm_pose": (24, 3, 3),
    "parm_shape": (10,),
    "bbox_center": (2,),
    "bbox_scale": (),
    "gt_keypoint_2d": (49, 3),
}


def read_coco(root: Path, split: str) -> BodySamples:
    """COCO 2014 train people with EFT fits (COCO2014-All-ver01.json); `split` must be "train"."""
    # SPIN/EFT's COCO scale is 1.2 x the longest side of the annotated box / 200.
    return _read(Path(root), split, "COCO2014-All-ver01.json", "train2014", SPIN_24_SLOTS_OF_COCO_17,
                 COCO_17_TO_BODY_25, expansion=1.2)


def read_mpii(root: Path, split: str) -> BodySamples:
    """MPII people with EFT fits (MPII_ver01.json); `split` must be "train"."""
    # MPII's scale is the annotated person height / 200.
    return _read(Path(root), split, "MPII_ver01.json", "images", SPIN_24_SLOTS_OF_MPII_16, MPII_16_TO_BODY_25,
                 expansion=1.0)


def _read(
    root: Path,
    split: str,
    json_name: str,
    image_dir: str,
    slots: Int[np.ndarray, "J"],
    index: Int[np.ndarray, "25"],
    expansion: float,
) -> BodySamples:
    if split != "train":
        raise ValueError(f"split {split!r}: EFT fitted the training set only, use 'train'")
    path = root / "eft_fit" / json_name
    entries = _entries(path)
    fields = {key: _stack(path, entries, key, shape) for key, shape in _ENTRY_SHAPES.items()}
    rotvecs = _rotvecs(path, fields["parm_pose"][:, :22])
    keypoints = fields["gt_keypoint_2d"]
    labels = BodyLabels(
        box=box_from_center_scale(fields["bbox_center"], fields["bbox_scale"], expansion),
        joints_2d=fill_from_openpose(spin_to_body_25(keypoints[:, 25:], slots, index), keypoints[:, :25], index),
        joints_3d=np.full((len(entries), NUM_BODY_JOINTS, 3), np.nan, np.float32),
        global_orient=rotvecs[:, 0],
        body_pose=rotvecs[:, 1:],
        betas=fields["parm_shape"],
    )
    return BodySamples(tuple(root / image_dir / Path(name).name for name in _image_names(path, entries)), labels)


def _entries(path: Path) -> list[dict]:
    if not path.is_file():
        raise FileNotFoundError(f"{path}: EFT fit file not found (get it with EFT's scripts/download_eft.sh)")
    try:
        content = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        raise ValueError(f"{path}: not valid JSON ({error})") from error
    entries = content.get("data") if isinstance(content, dict) else None
    if not isinstance(entries, list) or not entries or not all(isinstance(entry, dict) for entry in entries):
        raise ValueError(f'{path}: expected {{"ver": ..., "data": [one object per person, ...]}} with people')
    for i, entry in enumerate(entries):
        if entry.get("smpltype", "smpl") != "smpl":
            raise ValueError(f"{path}: data[{i}] smpltype is {entry['smpltype']!r}, only SMPL fits are supported")
    return entries


def _stack(path: Path, entries: list[dict], key: str, shape: tuple[int, ...]) -> Float[np.ndarray, "N ..."]:
    """One key of every entry as an (N, *shape) float32 array."""
    rows = []
    for i, entry in enumerate(entries):
        if key not in entry:
            raise ValueError(f"{path}: data[{i}] has no {key!r}")
        row = np.asarray(entry[key], np.float32)
        if row.shape != shape:
            raise ValueError(f"{path}: data[{i}][{key!r}] has shape {row.shape}, expected {shape}")
        rows.append(row)
    return np.stack(rows)


def _image_names(path: Path, entries: list[dict]) -> list[str]:
    for i, entry in enumerate(entries):
        if not isinstance(entry.get("imageName"), str):
            raise ValueError(f"{path}: data[{i}] has no 'imageName' string")
    return [entry["imageName"] for entry in entries]


def _rotvecs(path: Path, rotmats: Float[np.ndarray, "N 22 3 3"]) -> Float[np.ndarray, "N 22 3"]:
    """Axis-angle of the rotations, after checking they are rotations (orthonormal, determinant +1)."""
    error = np.abs(rotmats @ np.swapaxes(rotmats, -1, -2) - np.eye(3, dtype=np.float32)).max(axis=(-2, -1))
    bad = ~((error <= 1e-3) & (np.linalg.det(rotmats) > 0))
    if bad.any():
        raise ValueError(f"{path}: data[{np.flatnonzero(bad.any(axis=1))[0]}]['parm_pose'] holds non-rotations")
    return np.asarray(rotmat_to_rotvec(rotmats), np.float32)
