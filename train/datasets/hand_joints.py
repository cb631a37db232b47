"""Shared by the hand dataset adapters: joint re-orderings into OpenPose's hand order, pinhole projection, the hand
box's margin, FrankMocap's knuckle-length rescaling of 3D joints, and the lazy sequence of samples they return.

OpenPose hand order: wrist, thumb 1-4, index 1-4, middle 1-4, ring 1-4, pinky 1-4 (1 = the base joint, 4 = the tip).
"""

import pickle
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from jaxtyping import Bool, Float, Int

from smplx_jax import safe_pickle
from train.datasets.sample import NUM_HAND_JOINTS, HandSample, box_of_joints, read_colour_image

# OPENPOSE_FROM_X[i] = index, in dataset X's order, of OpenPose hand joint i.
OPENPOSE_FROM_MANO = np.array([0, 13, 14, 15, 16, 1, 2, 3, 17, 4, 5, 6, 18, 10, 11, 12, 19, 7, 8, 9, 20])
"""MANO's 16 joints (wrist, index, middle, pinky, ring, thumb) + tips thumb, index, middle, ring, pinky (HO-3D)."""
OPENPOSE_FROM_RHD = np.array([0, 4, 3, 2, 1, 8, 7, 6, 5, 12, 11, 10, 9, 16, 15, 14, 13, 20, 19, 18, 17])
"""RHD: wrist, then each finger (thumb, index, middle, ring, pinky) from tip to base."""
OPENPOSE_FROM_STB = np.array([0, 17, 18, 19, 20, 13, 14, 15, 16, 9, 10, 11, 12, 5, 6, 7, 8, 1, 2, 3, 4])
"""STB: palm centre, then pinky, ring, middle, index, thumb, each from base to tip."""

WRIST, MIDDLE_MCP, MIDDLE_PIP = 0, 9, 10
KNUCKLE_BONE = (MIDDLE_MCP, MIDDLE_PIP)
"""The middle finger's knuckle bone (MCP to PIP, OpenPose indices): FrankMocap's scale reference for 3D joints."""

BOX_MARGIN = 0.1
"""Each side of a box made from joints grows by this fraction of the box's longer side."""


def project(joints_3d: Float[np.ndarray, "J 3"], camera_matrix: Float[np.ndarray, "3 3"]) -> Float[np.ndarray, "J 2"]:
    """Pixels of camera-frame points (x right, y down, z forward) under a pinhole camera matrix."""
    homogeneous = joints_3d @ np.asarray(camera_matrix, np.float64).T
    return homogeneous[:, :2] / homogeneous[:, 2:]


def knuckle_length(joints_3d: Float[np.ndarray, "21 3"]) -> float:
    """Length of the middle finger's knuckle bone (`KNUCKLE_BONE`)."""
    return np.linalg.norm(joints_3d[KNUCKLE_BONE[1]] - joints_3d[KNUCKLE_BONE[0]])


def rescale_by_knuckle(joints_3d: Float[np.ndarray, "21 3"], reference_length: float) -> Float[np.ndarray, "21 3"]:
    """Scale the hand about its wrist so that its middle-finger knuckle is `reference_length` long.

    FrankMocap (section 3.2): "rescaling all 3D keypoint annotations to be compatible with our hand model, by using
    the middle finger's knuckle length as a reference"; its authors did it per sample (frankmocap issue #68).
    The trainer applies it with its hand model's length; adapters keep metric labels, consistent with the 2D ones.
    """
    wrist = joints_3d[WRIST]
    return wrist + (joints_3d - wrist) * (reference_length / knuckle_length(joints_3d))


@dataclass(frozen=True)
class HandLabels:
    """Labels of N hands, parsed once; `HandSamples` pairs them with images read on demand."""

    boxes: Float[np.ndarray, "N 4"]
    joints_2d: Float[np.ndarray, "N 21 2"]
    joints_3d: Float[np.ndarray, "N 21 3"]
    wrist_rotvec: Float[np.ndarray, "N 3"]
    hand_pose: Float[np.ndarray, "N 15 3"]
    betas: Float[np.ndarray, "N 10"]
    is_left: Bool[np.ndarray, "N"]


def hand_labels(
    joints_2d: Float[np.ndarray, "N 21 2"],
    *,
    joints_3d: Float[np.ndarray, "N 21 3"] | None = None,
    boxes: Float[np.ndarray, "N 4"] | None = None,
    wrist_rotvec: Float[np.ndarray, "N 3"] | None = None,
    hand_pose: Float[np.ndarray, "N 15 3"] | None = None,
    betas: Float[np.ndarray, "N 10"] | None = None,
    is_left: bool | Bool[np.ndarray, "N"] = False,
) -> HandLabels:
    """Read-only `HandLabels`: NaN for what a dataset does not label, boxes from the 2D joints where it has none."""
    n = len(joints_2d)

    def filled(values, shape):
        array = np.full((n, *shape), np.nan, np.float32) if values is None else np.array(values, np.float32)
        array.setflags(write=False)  # samples are views into these: a trainer editing one in place fails loudly
        return array

    joints_2d = filled(joints_2d, (NUM_HAND_JOINTS, 2))
    if boxes is None:
        boxes = np.stack([box_of_joints(j, BOX_MARGIN) for j in joints_2d]) if n else np.zeros((0, 4), np.float32)
        if np.isnan(boxes).any():
            raise ValueError("hand_labels: a hand has no box and no labelled joint to make one from (all NaN)")
    return HandLabels(
        boxes=filled(boxes, (4,)),
        joints_2d=joints_2d,
        joints_3d=filled(joints_3d, (NUM_HAND_JOINTS, 3)),
        wrist_rotvec=filled(wrist_rotvec, (3,)),
        hand_pose=filled(hand_pose, (15, 3)),
        betas=filled(betas, (10,)),
        is_left=np.broadcast_to(np.asarray(is_left, bool), (n,)),
    )


@dataclass(frozen=True)
class HandSamples(Sequence):  # of HandSample; Sequence[HandSample] would make runtime checkers load one
    """`HandSample`s whose images are read when indexed; image i has labels `label_index[i]`."""

    image_paths: tuple[Path, ...]
    labels: HandLabels
    label_index: Int[np.ndarray, "M"]

    def __len__(self) -> int:
        return len(self.image_paths)

    def __getitem__(self, i: int) -> HandSample:
        if not -len(self) <= i < len(self):
            raise IndexError(f"sample {i} out of range for {len(self)} samples")
        j = self.label_index[i]
        labels = self.labels
        return HandSample(
            image=read_colour_image(self.image_paths[i]),
            box=labels.boxes[j],
            joints_2d=labels.joints_2d[j],
            joints_3d=labels.joints_3d[j],
            wrist_rotvec=labels.wrist_rotvec[j],
            hand_pose=labels.hand_pose[j],
            betas=labels.betas[j],
            is_left=bool(labels.is_left[j]),
        )


def hand_samples(image_paths: Sequence[Path], labels: HandLabels) -> HandSamples:
    """One image per label."""
    return HandSamples(tuple(image_paths), labels, np.arange(len(image_paths)))


def check_split(dataset: str, split: str, splits: Collection[str]) -> None:
    """Raise ValueError unless `split` is one of `splits`."""
    if split not in splits:
        raise ValueError(f"{dataset}: unknown split {split!r}; expected one of {list(splits)}")


def require_file(path: Path, expected: str) -> Path:
    """`path` if it is a file, else FileNotFoundError naming it and what it should hold."""
    if not path.is_file():
        raise FileNotFoundError(f"{path}: missing; expected {expected}")
    return path


def load_pickled_dict(path: Path, expected: str) -> dict:
    """The dict pickled (by Python 2, hence latin1) in ``path``, numpy arrays and plain containers only (nothing in
    the file is run); errors name the file and ``expected``."""
    require_file(path, expected)
    try:
        with path.open("rb") as file:
            values = safe_pickle.load(file)
    except safe_pickle.RefusedPickle as error:
        raise ValueError(f"{path} {error}, which {expected} does not hold: refused before anything in it was "
                         "run") from None
    except (pickle.UnpicklingError, EOFError, ValueError) as error:
        raise ValueError(f"{path}: corrupt pickle ({error})") from None
    if not isinstance(values, dict):
        raise ValueError(f"{path}: expected {expected}, got {type(values).__name__}")
    return values


def checked_array(values, shape: tuple[int, ...], source: str | Path, what: str) -> np.ndarray:
    """`values` as a float array of `shape` (-1 = any length), else ValueError naming the source and shapes."""
    try:
        array = np.asarray(values, np.float64)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{source}: {what} is not numeric ({error})") from None
    if array.ndim != len(shape) or any(s not in (-1, a) for s, a in zip(shape, array.shape)):
        raise ValueError(f"{source}: {what} has shape {array.shape}, expected {shape}")
    return array
