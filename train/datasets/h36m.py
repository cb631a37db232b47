"""Human3.6M in SPIN's preprocessed npz layout (nkolot/SPIN datasets/preprocess/h36m.py, h36m_train.py).

Layout: ``ROOT/h36m_<split>.npz`` (splits: train, valid_protocol1, valid_protocol2) with the images at
``ROOT/<imgname>`` (SPIN names them ``images/S9_Directions_1.54138969_000001.jpg``).

Keys, N people: `imgname` (N,) str, `center` (N,2) pixels, `scale` (N,) (0.9 x the longest side of the person
mask / 200), and where the file has them: `part` (N,24,3) 2D pixels + confidence and `S` (N,24,4) 3D metres +
confidence in SPIN's 24 slots, `openpose` (N,25,3), `pose` (N,72) SMPL axis-angle and `shape` (N,10) SMPL betas
(MoSh fits, not public), `has_smpl` (N,). `S` is in the camera frame (x right, y down, z forward) with the pelvis
subtracted, so BODY_25's MidHip is at the origin; `pose[:3]` maps SMPL's y-up frame into the camera frame.
Missing labels are NaN; betas stay SMPL's (not SMPL-X's shape space).
"""

import zipfile
from pathlib import Path

import numpy as np
from jaxtyping import Float

from train.datasets.body_joints import (
    H36M_17_TO_BODY_25,
    SPIN_24_SLOTS_OF_H36M_17,
    BodyLabels,
    BodySamples,
    box_from_center_scale,
    fill_from_openpose,
    spin_to_body_25,
)
from train.datasets.sample import NUM_BODY_JOINTS

SPLITS = ("train", "valid_protocol1", "valid_protocol2")
_SHAPES = {
    "imgname": (),
    "center": (2,),
    "scale": (),
    "part": (24, 3),
    "S": (24, 4),
    "openpose": (25, 3),
    "pose": (72,),
    "shape": (10,),
    "has_smpl": (),
}
_REQUIRED = ("imgname", "center", "scale")
_MAX_METRES = 10.0  # a joint farther than this from the pelvis means the file holds millimetres


def read(root: Path, split: str) -> BodySamples:
    """The people of one split, labels parsed now, images read on access."""
    if split not in SPLITS:
        raise ValueError(f"split {split!r}: expected one of {SPLITS}")
    path = Path(root) / f"h36m_{split}.npz"
    arrays = _load(path)
    count = len(arrays["imgname"])
    joints_2d = np.full((count, NUM_BODY_JOINTS, 2), np.nan, np.float32)
    if "part" in arrays:
        joints_2d = spin_to_body_25(arrays["part"], SPIN_24_SLOTS_OF_H36M_17, H36M_17_TO_BODY_25)
    if "openpose" in arrays:
        joints_2d = fill_from_openpose(joints_2d, arrays["openpose"], H36M_17_TO_BODY_25)
    joints_3d = np.full((count, NUM_BODY_JOINTS, 3), np.nan, np.float32)
    if "S" in arrays:
        joints_3d = spin_to_body_25(arrays["S"], SPIN_24_SLOTS_OF_H36M_17, H36M_17_TO_BODY_25)
    pose, betas = _smpl(arrays, count)
    labels = BodyLabels(
        box=box_from_center_scale(arrays["center"], arrays["scale"], expansion=0.9),
        joints_2d=joints_2d,
        joints_3d=joints_3d,
        global_orient=pose[:, :3],
        body_pose=pose[:, 3:66].reshape(count, 21, 3),
        betas=betas,
    )
    return BodySamples(tuple(Path(root) / str(name) for name in arrays["imgname"]), labels)


def _load(path: Path) -> dict[str, np.ndarray]:
    """The npz arrays this adapter reads, checked for presence, shape and units."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: not found (SPIN's Human3.6M labels, datasets/preprocess/h36m*.py)")
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {key: npz[key] for key in npz.files if key in _SHAPES}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as error:
        raise ValueError(f"{path}: not a readable npz of arrays ({error})") from error
    for key in _REQUIRED:
        if key not in arrays:
            raise ValueError(f"{path}: missing key {key!r} (has {sorted(arrays)})")
    if arrays["imgname"].dtype.kind != "U":
        raise ValueError(f"{path}: 'imgname' has dtype {arrays['imgname'].dtype}, expected strings")
    count = len(arrays["imgname"])
    for key, array in arrays.items():
        if array.shape != (count, *_SHAPES[key]):
            raise ValueError(f"{path}: {key!r} has shape {array.shape}, expected {(count, *_SHAPES[key])}")
    if "S" in arrays and np.abs(arrays["S"][..., :3]).max(initial=0.0) > _MAX_METRES:
        raise ValueError(f"{path}: 'S' has joints over {_MAX_METRES} m from the pelvis, expected metres")
    if ("pose" in arrays) != ("shape" in arrays):
        raise ValueError(f"{path}: has one of 'pose' and 'shape' without the other")
    return arrays


def _smpl(arrays: dict[str, np.ndarray], count: int) -> tuple[Float[np.ndarray, "N 72"], Float[np.ndarray, "N 10"]]:
    """SMPL pose and betas, NaN for the people without a fit (no `pose` key, or `has_smpl` 0)."""
    if "pose" not in arrays:
        return np.full((count, 72), np.nan, np.float32), np.full((count, 10), np.nan, np.float32)
    fitted = (arrays["has_smpl"] > 0 if "has_smpl" in arrays else np.ones(count, bool))[:, None]
    return (np.where(fitted, arrays["pose"], np.nan).astype(np.float32),
            np.where(fitted, arrays["shape"], np.nan).astype(np.float32))
