"""Hand dataset adapters read tiny fixtures written in each dataset's real on-disk format."""

import json
import pickle

import cv2
import numpy as np
import pytest
import scipy.io

from train.datasets import freihand, ho3d, mpii_nzsl, rhd, stb
from train.datasets.hand_joints import BOX_MARGIN, hand_labels, knuckle_length, rescale_by_knuckle
from train.datasets.sample import box_of_joints

CAMERA = np.array([[500.0, 0.0, 32.0], [0.0, 480.0, 24.0], [0.0, 0.0, 1.0]])


def right_hand(depth: float = 0.5) -> np.ndarray:
    """21 distinct joints in OpenPose order, metres, camera frame: fingers point up (-y), the thumb far to -x."""
    wrist = np.array([0.0, 0.04, depth])
    joints = [wrist]
    bases = {0: (-0.03, 0.02), 1: (-0.02, 0.0), 2: (0.0, -0.005), 3: (0.02, 0.0), 4: (0.035, 0.01)}
    for finger, (x, y) in bases.items():
        step = np.array([-0.012, 0.0, 0.002]) if finger == 0 else np.array([0.001 * finger, -0.02, 0.003])
        base = wrist + np.array([x, y, 0.001 * finger])
        joints += [base + k * step for k in range(4)]
    return np.array(joints)


def projected(joints: np.ndarray, camera: np.ndarray = CAMERA) -> np.ndarray:
    return np.stack(
        [
            camera[0, 0] * joints[:, 0] / joints[:, 2] + camera[0, 2],
            camera[1, 1] * joints[:, 1] / joints[:, 2] + camera[1, 2],
        ],
        axis=1,
    )


def write_image(path, height=48, width=64):
    path.parent.mkdir(parents=True, exist_ok=True)
    assert cv2.imwrite(str(path), np.full((height, width, 3), 128, np.uint8))


def rotation(axis, degrees) -> np.ndarray:
    return cv2.Rodrigues(np.asarray(axis, float) / np.linalg.norm(axis) * np.radians(degrees))[0]


def check_sample(sample, joints_2d, joints_3d, is_left, image_shape=(48, 64, 3)):
    assert sample.image.shape == image_shape and sample.image.dtype == np.uint8
    np.testing.assert_allclose(sample.joints_2d, joints_2d, rtol=1e-5, atol=1e-3, equal_nan=True)
    np.testing.assert_allclose(sample.joints_3d, joints_3d, rtol=1e-5, atol=1e-6, equal_nan=True)
    assert sample.is_left is is_left
    x, y, w, h = sample.box
    labelled = sample.joints_2d[np.isfinite(sample.joints_2d).all(axis=1)]
    assert (labelled >= [x, y]).all() and (labelled <= [x + w, y + h]).all()


def test_thumb_tip_is_far_from_wrist_towards_minus_x():
    hand = right_hand()
    assert np.argmin(hand[:, 0]) == 4 and np.argmin(hand[:, 1]) == 12  # thumb tip leftmost, middle tip highest


# FreiHAND: OpenPose order already, metres, OpenCV frame; 4 image versions share each label.
def write_freihand(root, hands, set_name="training", versions=4):
    mano = [
        [list(np.r_[[0.1 * i, 0.2, 0.3], np.full(45, 0.5), np.arange(10) / 10, [0.0, 0.0, 0.5]])]
        for i in range(len(hands))
    ]
    (root / f"{set_name}_xyz.json").write_text(json.dumps([h.tolist() for h in hands]))
    (root / f"{set_name}_K.json").write_text(json.dumps([CAMERA.tolist()] * len(hands)))
    (root / f"{set_name}_mano.json").write_text(json.dumps(mano))
    (root / f"{set_name}_scale.json").write_text(json.dumps([0.03] * len(hands)))
    for i in range(versions * len(hands)):
        write_image(root / set_name / "rgb" / f"{i:08d}.jpg")


def test_freihand_train_versions_share_labels(tmp_path):
    hands = [right_hand(0.5), right_hand(0.6)]
    write_freihand(tmp_path, hands)
    samples = freihand.read(tmp_path, "train")
    assert len(samples) == 8
    for i in range(8):
        check_sample(samples[i], projected(hands[i % 2]), hands[i % 2], is_left=False)
    sample = samples[3]
    np.testing.assert_allclose(sample.wrist_rotvec, [0.1, 0.2, 0.3], rtol=1e-6)
    np.testing.assert_allclose(sample.betas, np.arange(10) / 10, rtol=1e-6)
    assert np.isnan(sample.hand_pose).all()  # mean-relative in FreiHAND: unknown as absolute pose
    with pytest.raises(ValueError, match="read-only"):
        sample.joints_3d[0, 0] = 1.0


def test_freihand_evaluation_and_missing_files(tmp_path):
    write_freihand(tmp_path, [right_hand()], "evaluation", versions=1)
    assert len(freihand.read(tmp_path, "test")) == 1
    (tmp_path / "evaluation" / "rgb" / "00000000.jpg").unlink()
    with pytest.raises(FileNotFoundError, match="00000000.jpg"):
        freihand.read(tmp_path, "test")[0]
    (tmp_path / "evaluation_K.json").unlink()
    with pytest.raises(FileNotFoundError, match="evaluation_K.json"):
        freihand.read(tmp_path, "test")
    with pytest.raises(ValueError, match="split"):
        freihand.read(tmp_path, "val")


def test_freihand_mis_shaped_joints_name_the_file(tmp_path):
    write_freihand(tmp_path, [right_hand()])
    (tmp_path / "training_xyz.json").write_text(json.dumps([np.zeros((20, 3)).tolist()]))
    with pytest.raises(ValueError, match=r"training_xyz.json.*\(1, 20, 3\)"):
        freihand.read(tmp_path, "train")


# HO-3D: MANO joint order + tips, OpenGL camera frame (y up, z backwards).
MANO_ORDER = [0, 5, 6, 7, 9, 10, 11, 17, 18, 19, 13, 14, 15, 1, 2, 3, 4, 8, 12, 16, 20]  # OpenPose index of each
OPENGL = np.diag([1.0, -1.0, -1.0])


def write_ho3d(root, hand, wrist_cv, image_suffix):
    train = root / "train" / "SEQ1"
    meta = {
        "handJoints3D": hand[MANO_ORDER] @ OPENGL,
        "camMat": CAMERA,
        "handBeta": np.arange(10) / 10,
        "handPose": np.r_[cv2.Rodrigues(OPENGL @ wrist_cv)[0][:, 0], np.linspace(-0.5, 0.5, 45)],
        "handTrans": np.zeros(3),
        "objRot": np.zeros(3),
    }
    unlabelled = dict(meta, handJoints3D=None, handPose=None)
    evaluation = {"handJoints3D": hand[0] @ OPENGL, "camMat": CAMERA, "handBoundingBox": np.array([5, 6, 60, 70])}
    for split_dir, frame, labels in [
        (train, "0000", meta),
        (train, "0001", unlabelled),
        (root / "evaluation" / "SEQ2", "0000", evaluation),
    ]:
        (split_dir / "meta").mkdir(parents=True, exist_ok=True)
        (split_dir / "meta" / f"{frame}.pkl").write_bytes(pickle.dumps(labels, protocol=2))
        write_image(split_dir / "rgb" / f"{frame}{image_suffix}")
    (root / "train.txt").write_text("SEQ1/0000\nSEQ1/0001\n")
    (root / "evaluation.txt").write_text("SEQ2/0000\n")


@pytest.mark.parametrize("image_suffix", [".png", ".jpg"])  # v2, v3
def test_ho3d_converts_opengl_frame_and_mano_order(tmp_path, image_suffix):
    hand, wrist_cv = right_hand(), rotation([0.2, 1.0, 0.3], 70)
    write_ho3d(tmp_path, hand, wrist_cv, image_suffix)
    samples = ho3d.read(tmp_path, "train")
    assert len(samples) == 1  # the frame without hand labels is skipped
    sample = samples[0]
    check_sample(sample, projected(hand), hand, is_left=False)
    assert sample.joints_3d[:, 2].min() > 0 and sample.joints_3d[12, 1] < sample.joints_3d[0, 1]  # ahead; tip up
    np.testing.assert_allclose(cv2.Rodrigues(sample.wrist_rotvec.astype(float))[0], wrist_cv, atol=1e-6)
    np.testing.assert_allclose(sample.hand_pose.reshape(-1), np.linspace(-0.5, 0.5, 45), rtol=1e-6)
    np.testing.assert_allclose(sample.betas, np.arange(10) / 10, rtol=1e-6)


def test_ho3d_evaluation_has_wrist_and_box_only(tmp_path):
    hand = right_hand()
    write_ho3d(tmp_path, hand, np.eye(3), ".png")
    (sample,) = ho3d.read(tmp_path, "test")
    expected_3d = np.full((21, 3), np.nan)
    expected_3d[0] = hand[0]
    check_sample(sample, projected(expected_3d), expected_3d, is_left=False)
    np.testing.assert_allclose(sample.box, [5, 6, 55, 64])
    assert np.isnan(sample.hand_pose).all() and np.isnan(sample.wrist_rotvec).all()
    (tmp_path / "evaluation" / "SEQ2" / "meta" / "0000.pkl").unlink()
    with pytest.raises(FileNotFoundError, match="0000.pkl"):
        ho3d.read(tmp_path, "test")


# RHD: left hand 0-20, right 21-41; each: wrist, then thumb..pinky from tip to base.
def rhd_order(hand):
    return np.stack([hand[0]] + [hand[1 + 4 * finger + 3 - k] for finger in range(5) for k in range(4)])


def test_rhd_picks_the_more_visible_hand(tmp_path):
    left = right_hand() * [-1, 1, 1] + [0.0, 0.0, 0.0]
    right = right_hand(0.6)
    samples_in = {}
    for sample_id, visible_left in [(0, 21), (7, 3)]:
        uv = np.concatenate([projected(rhd_order(left)), projected(rhd_order(right))])
        visible = np.r_[np.arange(21) < visible_left, np.arange(21) < 12].astype(float)
        samples_in[sample_id] = {
            "xyz": np.concatenate([rhd_order(left), rhd_order(right)]),
            "uv_vis": np.c_[uv, visible],
            "K": CAMERA,
        }
        write_image(tmp_path / "training" / "color" / f"{sample_id:05d}.png", 32, 32)
    (tmp_path / "training" / "anno_training.pickle").write_bytes(pickle.dumps(samples_in, protocol=2))
    first, second = rhd.read(tmp_path, "train")
    check_sample(first, projected(left), left, is_left=True, image_shape=(32, 32, 3))
    check_sample(second, projected(right), right, is_left=False, image_shape=(32, 32, 3))
    assert np.isnan(first.hand_pose).all() and np.isnan(first.betas).all()
    with pytest.raises(FileNotFoundError, match="anno_evaluation.pickle"):
        rhd.read(tmp_path, "test")


# STB: palm, then pinky, ring, middle, index, thumb from base to tip; millimetres in the SK depth camera's frame.
def stb_hand_para(hands_color):
    rotation_sk = cv2.Rodrigues(np.array([0.00531, -0.01196, 0.00301]))[0]
    translation_mm = np.array([-24.0381, -0.4563, -1.2326])
    frames = []
    for hand in hands_color:
        palm = hand[9] + (hand[0] - hand[9]) / 2.2
        stb_order = [palm] + [hand[1 + 4 * finger + k] for finger in (4, 3, 2, 1, 0) for k in range(4)]
        frames.append(1000.0 * np.stack(stb_order) @ rotation_sk.T + translation_mm)
    return np.transpose(np.stack(frames), (2, 1, 0))  # (3, 21, F)


def test_stb_millimetres_palm_to_wrist_and_sk_camera(tmp_path):
    left = right_hand() * [-1, 1, 1]
    hands = {"B1Counting": [left, left + [0.01, 0, 0]], "B1Random": [left + [0, 0, 0.1]]}
    (tmp_path / "labels").mkdir()
    for seq, seq_hands in hands.items():
        scipy.io.savemat(tmp_path / "labels" / f"{seq}_SK.mat", {"handPara": stb_hand_para(seq_hands)})
        for i in range(len(seq_hands)):
            write_image(tmp_path / "images" / seq / f"SK_color_{i}.png", 48, 64)
    samples = stb.read(tmp_path, "test")
    expected = hands["B1Counting"] + hands["B1Random"]
    assert len(samples) == 3
    sk_color = np.array([[607.92271, 0, 314.78337], [0, 607.88192, 236.42484], [0, 0, 1]])
    for sample, hand in zip(samples, expected):
        check_sample(sample, projected(hand, sk_color), hand, is_left=True)
    with pytest.raises(FileNotFoundError, match="B2Counting_SK.mat"):
        stb.read(tmp_path, "train")
    scipy.io.savemat(tmp_path / "labels" / "B1Random_SK.mat", {"joints": np.zeros((3, 21, 1))})
    with pytest.raises(ValueError, match="B1Random_SK.mat.*handPara"):
        stb.read(tmp_path, "test")


# MPII+NZSL: OpenPose order, 2D pixels with an annotated flag; one JSON per hand image.
def test_mpii_nzsl_2d_only_with_unlabelled_points_nan(tmp_path):
    folder = tmp_path / "hand_labels" / "manual_test"
    points = projected(right_hand())
    flags = np.ones(21)
    flags[[4, 20]] = 0
    for name, is_left in [("Ex1_a_01_l", 1), ("Ex1_a_01_r", 0)]:
        write_image(folder / f"{name}.jpg", 40, 30)
        label = {
            "hand_pts": np.c_[points, flags].tolist(),
            "is_left": is_left,
            "is_mpii": 0,
            "hand_box_center": [30.0, 20.0],
        }
        (folder / f"{name}.json").write_text(json.dumps(label))
    left, right = mpii_nzsl.read(tmp_path, "test")
    expected = np.where(flags[:, None] == 1, points, np.nan)
    check_sample(left, expected, np.full((21, 3), np.nan), is_left=True, image_shape=(40, 30, 3))
    check_sample(right, expected, np.full((21, 3), np.nan), is_left=False, image_shape=(40, 30, 3))
    assert np.isnan(left.betas).all() and np.isnan(left.wrist_rotvec).all()
    with pytest.raises(FileNotFoundError, match="manual_train"):
        mpii_nzsl.read(tmp_path, "train")
    (folder / "Ex1_a_01_r.json").write_text("{not json")
    with pytest.raises(ValueError, match="Ex1_a_01_r.json"):
        mpii_nzsl.read(tmp_path, "test")


def test_rescale_by_knuckle_keeps_wrist_and_directions():
    hand = right_hand()
    rescaled = rescale_by_knuckle(hand, 0.05)
    np.testing.assert_allclose(knuckle_length(rescaled), 0.05)
    np.testing.assert_allclose(knuckle_length(hand), np.linalg.norm(hand[10] - hand[9]))
    np.testing.assert_allclose(rescaled[0], hand[0])
    scale = 0.05 / knuckle_length(hand)
    np.testing.assert_allclose(rescaled - hand[0], (hand - hand[0]) * scale)


def test_box_covers_labelled_joints_with_margin():
    joints = np.array([[10.0, 20.0], [30.0, 25.0], [np.nan, np.nan], [1000.0, np.nan]])
    np.testing.assert_allclose(box_of_joints(joints, BOX_MARGIN), [8.0, 18.0, 24.0, 9.0])
    with pytest.raises(ValueError, match="no labelled joint"):
        hand_labels(np.full((1, 21, 2), np.nan))
