"""Body dataset adapters on tiny files written in the real layouts: EFT json (COCO, MPII) and SPIN's Human3.6M npz.

The fixtures fill SPIN's 24 named slots from a standing person whose joints all sit at distinct places, so any
wrong joint order or slot shows up as a wrong coordinate.
"""

import json
import re
from pathlib import Path

import cv2
import numpy as np
import pytest

from train.datasets import body_joints, eft, h36m
from train.datasets.sample import box_of_joints

# OpenPose's BODY_25 output order (doc/02_output.md), in the adapters' snake_case names.
BODY_25_NAMES = (
    "nose", "neck", "right_shoulder", "right_elbow", "right_wrist", "left_shoulder", "left_elbow", "left_wrist",
    "mid_hip", "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee", "left_ankle", "right_eye",
    "left_eye", "right_ear", "left_ear", "left_big_toe", "left_small_toe", "left_heel", "right_big_toe",
    "right_small_toe", "right_heel",
)

# SPIN's constants.JOINT_NAMES[25:], the 24 annotated slots.
SPIN_24 = (
    "Right Ankle", "Right Knee", "Right Hip", "Left Hip", "Left Knee", "Left Ankle", "Right Wrist", "Right Elbow",
    "Right Shoulder", "Left Shoulder", "Left Elbow", "Left Wrist", "Neck (LSP)", "Top of Head (LSP)",
    "Pelvis (MPII)", "Thorax (MPII)", "Spine (H36M)", "Jaw (H36M)", "Head (H36M)", "Nose", "Left Eye", "Right Eye",
    "Left Ear", "Right Ear",
)
LIMBS = {name: name.lower().replace(" ", "_") for name in SPIN_24[:12]}
# What SPIN's preprocessing stores in each slot, per dataset (datasets/preprocess/{coco,mpii,h36m}.py).
COCO_SLOTS = LIMBS | {"Nose": "nose", "Left Eye": "left_eye", "Right Eye": "right_eye", "Left Ear": "left_ear",
                      "Right Ear": "right_ear"}
MPII_SLOTS = LIMBS | {"Pelvis (MPII)": "mid_hip", "Thorax (MPII)": "neck", "Neck (LSP)": "upper_neck",
                      "Top of Head (LSP)": "head_top"}
H36M_SLOTS = LIMBS | {"Pelvis (MPII)": "mid_hip", "Neck (LSP)": "neck", "Spine (H36M)": "spine",
                      "Jaw (H36M)": "neck_nose", "Head (H36M)": "head"}

# A person facing the camera (their right on the image's left), camera frame in metres, y down.
PERSON_XY = {
    "nose": (0.0, -0.75), "neck": (0.0, -0.55), "right_shoulder": (-0.2, -0.52), "right_elbow": (-0.28, -0.25),
    "right_wrist": (-0.3, 0.0), "left_shoulder": (0.21, -0.53), "left_elbow": (0.29, -0.26),
    "left_wrist": (0.32, 0.02), "mid_hip": (0.0, 0.0), "right_hip": (-0.1, 0.01), "right_knee": (-0.11, 0.45),
    "right_ankle": (-0.12, 0.88), "left_hip": (0.1, 0.015), "left_knee": (0.115, 0.46),
    "left_ankle": (0.125, 0.89), "right_eye": (-0.035, -0.79), "left_eye": (0.036, -0.785),
    "right_ear": (-0.08, -0.77), "left_ear": (0.082, -0.765), "left_big_toe": (0.15, 0.95),
    "left_small_toe": (0.2, 0.94), "left_heel": (0.12, 0.92), "right_big_toe": (-0.15, 0.951),
    "right_small_toe": (-0.2, 0.941), "right_heel": (-0.12, 0.921), "upper_neck": (0.0, -0.62),
    "head_top": (0.0, -0.95), "spine": (0.0, -0.2), "neck_nose": (0.01, -0.7), "head": (0.0, -0.85),
}
PERSON_3D = {name: np.array([x, y, 3.0 + 0.01 * i]) for i, (name, (x, y)) in enumerate(PERSON_XY.items())}
PERSON_2D = {name: 200.0 * point[:2] / point[2] + (160.0, 120.0) for name, point in PERSON_3D.items()}
IMAGE_SHAPE = (240, 320, 3)


def spin_24(points: dict, slots: dict, unlabelled: tuple = ()) -> np.ndarray:
    """SPIN's (24, D+1) label array: the named slots filled, confidence 1 (0 for `unlabelled` joints)."""
    dim = len(next(iter(points.values())))
    labels = np.zeros((24, dim + 1))
    for i, slot in enumerate(SPIN_24):
        if slot in slots:
            labels[i] = [*points[slots[slot]], slots[slot] not in unlabelled]
    return labels


def body_25(points: dict, names) -> np.ndarray:
    """BODY_25 array of `points` at `names`, NaN elsewhere."""
    dim = len(next(iter(points.values())))
    return np.array([points[name] if name in names else np.full(dim, np.nan) for name in BODY_25_NAMES])


def rotations(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """24 axis-angles (global near 180 degrees about x, as for an upright person in a y-down camera) and matrices."""
    rotvecs = np.random.default_rng(seed).normal(scale=0.3, size=(24, 3))
    rotvecs[0] = [np.pi - 0.05, 0.1, 0.02]
    return rotvecs, np.stack([cv2.Rodrigues(rotvec)[0] for rotvec in rotvecs])


def write_image(path: Path, value: int) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), np.full(IMAGE_SHAPE, (value, 90, 200), np.uint8))


def eft_entry(image_name: str, slots: dict, openpose: np.ndarray, seed: int, unlabelled: tuple = ()) -> dict:
    """One person as EFT's json holds it."""
    rotmats = rotations(seed)[1]
    return {
        "parm_pose": rotmats.tolist(),
        "parm_shape": np.linspace(-1, 1, 10).tolist(),
        "parm_cam": [0.9, 0.01, 0.2],
        "bbox_scale": 0.9,
        "bbox_center": [150.0, 100.0],
        "gt_keypoint_2d": np.concatenate([openpose, spin_24(PERSON_2D, slots, unlabelled)]).tolist(),
        "joint_validity_openpose18": [1] * 18,
        "smpltype": "smpl",
        "annotId": 1000 + seed,
        "imageName": image_name,
    }


def coco_openpose() -> np.ndarray:
    """EFT's COCO OpenPose slots: foot annotations, a neck, and decoys for joints COCO has (labelled or not)."""
    openpose = np.zeros((25, 3))
    for name in BODY_25_NAMES[19:] + ("neck",):
        openpose[BODY_25_NAMES.index(name)] = [*PERSON_2D[name], 1.0]
    openpose[BODY_25_NAMES.index("right_wrist")] = [5.0, 5.0, 1.0]
    openpose[BODY_25_NAMES.index("left_ear")] = [6.0, 6.0, 1.0]
    return openpose


def write_eft(root: Path, json_name: str, entries: list) -> None:
    (root / "eft_fit").mkdir(parents=True, exist_ok=True)
    (root / "eft_fit" / json_name).write_text(json.dumps({"ver": 0.1, "data": entries}))


@pytest.fixture
def coco_root(tmp_path) -> Path:
    write_image(tmp_path / "train2014" / "COCO_train2014_000000000036.jpg", 10)
    write_image(tmp_path / "train2014" / "COCO_train2014_000000000049.jpg", 120)
    write_eft(tmp_path, "COCO2014-All-ver01.json", [
        eft_entry("COCO_train2014_000000000036.jpg", COCO_SLOTS, coco_openpose(), 0, unlabelled=("left_ear",)),
        eft_entry("COCO_train2014_000000000049.jpg", COCO_SLOTS, np.zeros((25, 3)), 1),
    ])
    return tmp_path


def test_eft_coco_reads_labels_in_body_25(coco_root):
    samples = eft.read_coco(coco_root, "train")
    assert len(samples) == 2
    first, second = samples[0], samples[1]
    coco_names = set(COCO_SLOTS.values()) - {"left_ear"}
    expected = body_25(PERSON_2D, coco_names | set(BODY_25_NAMES[19:]) | {"neck"})
    np.testing.assert_allclose(first.joints_2d, expected, atol=1e-4)
    np.testing.assert_allclose(second.joints_2d, body_25(PERSON_2D, set(COCO_SLOTS.values())), atol=1e-4)
    assert np.isnan(first.joints_3d).all() and first.joints_3d.shape == (25, 3)
    # SPIN's COCO scale is 1.2 x the person's longest side / 200: side 200 * 0.9 / 1.2 = 150 around (150, 100).
    np.testing.assert_allclose(first.box, [75.0, 25.0, 150.0, 150.0])
    np.testing.assert_allclose(first.betas, np.linspace(-1, 1, 10), atol=1e-6)
    assert first.image.shape == IMAGE_SHAPE and first.image.dtype == np.uint8
    assert abs(int(first.image[..., 0].mean()) - 10) <= 2 and abs(int(second.image[..., 0].mean()) - 120) <= 2


@pytest.mark.parametrize("seed", [0, 1])
def test_eft_rotation_matrices_become_smplx_axis_angles(coco_root, seed):
    sample = eft.read_coco(coco_root, "train")[seed]
    rotvecs, rotmats = rotations(seed)
    assert sample.global_orient.shape == (3,) and sample.body_pose.shape == (21, 3)
    np.testing.assert_allclose(sample.global_orient, rotvecs[0], atol=1e-5)
    back = np.stack([cv2.Rodrigues(rotvec.astype(np.float64))[0] for rotvec in sample.body_pose])
    np.testing.assert_allclose(back, rotmats[1:22], atol=1e-5)


def test_eft_mpii_maps_pelvis_and_thorax(tmp_path):
    write_image(tmp_path / "images" / "015601864.jpg", 60)
    openpose = np.zeros((25, 3))
    openpose[BODY_25_NAMES.index("left_big_toe")] = [*PERSON_2D["left_big_toe"], 0.5]
    write_eft(tmp_path, "MPII_ver01.json", [eft_entry("015601864.jpg", MPII_SLOTS, openpose, 2)])
    sample = eft.read_mpii(tmp_path, "train")[0]
    expected = body_25(PERSON_2D, set(MPII_SLOTS.values()) | {"left_big_toe"})
    np.testing.assert_allclose(sample.joints_2d, expected, atol=1e-4)
    np.testing.assert_allclose(sample.box, [60.0, 10.0, 180.0, 180.0])  # MPII's scale is the person height / 200


def write_h36m(root: Path, split: str, **arrays) -> None:
    np.savez(root / f"h36m_{split}.npz", **arrays)


def h36m_arrays(count: int) -> dict:
    names = [f"images/S9_Directions_1.54138969_{i + 1:06d}.jpg" for i in range(count)]
    pelvis = PERSON_3D["mid_hip"]
    return {
        "imgname": np.array(names),
        "center": np.tile([150.0, 100.0], (count, 1)),
        "scale": np.full(count, 0.9),
        "S": np.stack([spin_24({k: v - pelvis for k, v in PERSON_3D.items()}, H36M_SLOTS)] * count),
    }


def test_h36m_train_reads_2d_3d_and_smpl(tmp_path):
    arrays = h36m_arrays(2)
    for i, name in enumerate(arrays["imgname"]):
        write_image(tmp_path / name, 30 + 50 * i)
    rotvecs = np.stack([rotations(3)[0], rotations(4)[0]])
    write_h36m(tmp_path, "train", **arrays, part=np.stack([spin_24(PERSON_2D, H36M_SLOTS)] * 2),
               pose=rotvecs.reshape(2, 72), shape=np.ones((2, 10)), has_smpl=np.array([1.0, 0.0]))
    samples = h36m.read(tmp_path, "train")
    first, second = samples[0], samples[1]
    names = set(H36M_SLOTS.values())
    np.testing.assert_allclose(first.joints_2d, body_25(PERSON_2D, names), atol=1e-4)
    pelvis_centred = {k: v - PERSON_3D["mid_hip"] for k, v in PERSON_3D.items()}
    np.testing.assert_allclose(first.joints_3d, body_25(pelvis_centred, names), atol=1e-6)
    np.testing.assert_allclose(first.joints_3d[BODY_25_NAMES.index("mid_hip")], 0.0)
    np.testing.assert_allclose(first.global_orient, rotvecs[0, 0], atol=1e-6)
    np.testing.assert_allclose(first.body_pose, rotvecs[0, 1:22], atol=1e-6)
    np.testing.assert_allclose(first.betas, 1.0)
    assert np.isnan(second.global_orient).all() and np.isnan(second.body_pose).all() and np.isnan(second.betas).all()
    # SPIN's H36M scale is 0.9 x the longest side of the person mask / 200: side 200 around (150, 100).
    np.testing.assert_allclose(first.box, [50.0, 0.0, 200.0, 200.0])
    assert abs(int(second.image[..., 0].mean()) - 80) <= 2


def test_h36m_validation_split_without_2d_or_smpl(tmp_path):
    write_h36m(tmp_path, "valid_protocol1", **h36m_arrays(1))
    samples = h36m.read(tmp_path, "valid_protocol1")
    assert len(samples) == 1
    labels = samples.labels
    assert np.isnan(labels.joints_2d).all() and np.isnan(labels.global_orient).all() and np.isnan(labels.betas).all()
    assert not np.isnan(labels.joints_3d[0, BODY_25_NAMES.index("right_wrist")]).any()


def test_missing_image_names_the_file(tmp_path):
    write_eft(tmp_path, "MPII_ver01.json", [eft_entry("000001.jpg", MPII_SLOTS, np.zeros((25, 3)), 0)])
    samples = eft.read_mpii(tmp_path, "train")
    with pytest.raises(FileNotFoundError, match=re.escape(str(tmp_path / "images" / "000001.jpg"))):
        samples[0]


def corrupt(entry: dict, key: str, value) -> dict:
    return {k: v for k, v in entry.items() if k != key} | ({} if value is None else {key: value})


@pytest.mark.parametrize("key, value, message", [
    ("parm_pose", None, "data[1] has no 'parm_pose'"),
    ("imageName", None, "data[1] has no 'imageName'"),
    ("gt_keypoint_2d", np.zeros((48, 3)).tolist(), "data[1]['gt_keypoint_2d'] has shape (48, 3), expected (49, 3)"),
    ("parm_pose", np.full((24, 3, 3), 2.0).tolist(), "data[1]['parm_pose'] holds non-rotations"),
    ("smpltype", "smplx", "data[1] smpltype is 'smplx'"),
])
def test_eft_bad_entry_names_file_and_key(tmp_path, key, value, message):
    good = eft_entry("a.jpg", COCO_SLOTS, np.zeros((25, 3)), 0)
    write_eft(tmp_path, "COCO2014-All-ver01.json", [good, corrupt(good, key, value)])
    with pytest.raises(ValueError, match=re.escape(message)) as error:
        eft.read_coco(tmp_path, "train")
    assert "COCO2014-All-ver01.json" in str(error.value)


def test_eft_missing_file_or_split(tmp_path):
    with pytest.raises(FileNotFoundError, match=re.escape(str(tmp_path / "eft_fit" / "MPII_ver01.json"))):
        eft.read_mpii(tmp_path, "train")
    with pytest.raises(ValueError, match="'val'"):
        eft.read_coco(tmp_path, "val")


@pytest.mark.parametrize("change, message", [
    (lambda a: a.pop("center"), "missing key 'center'"),
    (lambda a: a.update(part=np.zeros((1, 17, 3))), "'part' has shape (1, 17, 3), expected (1, 24, 3)"),
    (lambda a: a.update(S=a["S"] * 1000), "expected metres"),
    (lambda a: a.update(pose=np.zeros((1, 72))), "'pose' and 'shape'"),
])
def test_h36m_bad_file_names_file_and_key(tmp_path, change, message):
    arrays = h36m_arrays(1)
    change(arrays)
    write_h36m(tmp_path, "train", **arrays)
    with pytest.raises(ValueError, match=re.escape(message)) as error:
        h36m.read(tmp_path, "train")
    assert "h36m_train.npz" in str(error.value)


def test_h36m_missing_file_or_split(tmp_path):
    with pytest.raises(FileNotFoundError, match="h36m_valid_protocol2.npz"):
        h36m.read(tmp_path, "valid_protocol2")
    with pytest.raises(ValueError, match="'test'"):
        h36m.read(tmp_path, "test")


def test_body_25_names_follow_openpose():
    assert body_joints.BODY_25_NAMES == BODY_25_NAMES


def test_box_of_joints_ignores_unlabelled():
    joints = np.array([[10.0, 20.0], [np.nan, np.nan], [30.0, 5.0]])
    np.testing.assert_allclose(box_of_joints(joints), [10.0, 5.0, 20.0, 15.0])
    assert np.isnan(box_of_joints(np.full((25, 2), np.nan))).all()
