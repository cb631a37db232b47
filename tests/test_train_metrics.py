"""train.metrics against hand-computed values."""

import inspect

import numpy as np
import pytest

from train.metrics import joint_errors, mpjpe, pa_mpjpe, pck, pck_auc, pck_curve, procrustes_align, root_align


def test_root_align():
    joints = np.array([[[1.0, 2, 3], [4, 6, 8]]])
    np.testing.assert_array_equal(root_align(joints), [[[0, 0, 0], [3, 4, 5]]])
    np.testing.assert_array_equal(root_align(joints, 1), [[[-3, -4, -5], [0, 0, 0]]])


def test_mpjpe_by_hand():
    gt = np.zeros((2, 3, 3))
    pred = gt.copy()
    pred[0, 0] = [3, 4, 0]  # 5
    pred[0, 1] = [0, 0, 1]  # 1
    pred[0, 2] = [100, 0, 0]  # masked off
    pred[1, :] = [0, 6, 8]  # 10 each
    mask = np.array([[True, True, False], [True, True, True]])
    np.testing.assert_allclose(mpjpe(pred, gt, mask), [3.0, 10.0])
    np.testing.assert_allclose(joint_errors(pred, gt)[0], [5, 1, 100])
    all_masked = mpjpe(pred, gt, np.zeros((2, 3), bool))
    assert np.all(np.isnan(all_masked))


def test_pa_mpjpe_is_zero_for_a_similar_copy():
    rng = np.random.default_rng(0)
    gt = rng.normal(size=(3, 21, 3))
    angle = 0.7
    rotation = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    pred = 2.5 * gt @ rotation.T + [1.0, -2.0, 3.0]
    mask = np.ones((3, 21), bool)
    mask[1, :10] = False
    np.testing.assert_allclose(pa_mpjpe(pred, gt, mask), 0, atol=1e-9)
    assert np.all(mpjpe(pred, gt, mask) > 0.5)


def test_pa_mpjpe_ignores_masked_joints_and_rejects_reflections():
    gt = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    pred = gt * [1, 1, -1]  # a mirror image: no rotation maps it onto gt
    assert pa_mpjpe(pred[None], gt[None], np.ones((1, 4), bool))[0] > 0.1
    outlier = gt.copy()
    outlier[3] = [50, 50, 50]
    aligned = procrustes_align(outlier, gt, np.array([True, True, True, False]))
    np.testing.assert_allclose(aligned[:3], gt[:3], atol=1e-9)
    np.testing.assert_allclose(aligned[3], [50, 50, 50], atol=1e-9)


def test_pck_at_and_around_thresholds():
    errors = np.array([[10.0, 20.0, 30.0], [20.0, 40.0, 5.0]])
    mask = np.array([[True, True, True], [True, True, False]])
    # per joint at 20: joint 0 2/2, joint 1 1/2, joint 2 0/1 -> mean 0.5 (an error exactly on the threshold counts)
    assert pck(errors, 20.0, mask) == pytest.approx(0.5)
    np.testing.assert_allclose(pck_curve(errors, np.array([0.0, 10.0, 30.0, 40.0]), mask), [0.0, 1 / 6, 2.5 / 3, 1.0])
    assert np.isnan(pck(errors, 20.0, np.zeros((2, 3), bool)))


def test_pck_auc_by_hand():
    # one joint, errors 0, 20 and 40 over 0..40 with 3 thresholds (0, 20, 40): curve 1/3, 2/3, 1
    errors = np.array([[0.0], [20.0], [40.0]])
    mask = np.ones((3, 1), bool)
    assert pck_auc(errors, 0.0, 40.0, mask, steps=3) == pytest.approx((1 / 3 + 2 * 2 / 3 + 1) / 4)
    # all errors below the range: AUC 1; all above: 0; 20 steps (the default) on 20-50 mm
    assert pck_auc(np.full((4, 21), 19.9), 20.0, 50.0, np.ones((4, 21), bool)) == pytest.approx(1.0)
    assert pck_auc(np.full((4, 21), 50.1), 20.0, 50.0, np.ones((4, 21), bool)) == pytest.approx(0.0)
    # errors uniform at 35 mm: PCK 0 below, 1 from the first threshold >= 35 (35.789..) on
    thresholds = np.linspace(20, 50, 20)
    first = np.argmax(thresholds >= 35)
    expected = (0.5 * (thresholds[first] - thresholds[first - 1]) + (50 - thresholds[first])) / 30
    assert pck_auc(np.full((2, 21), 35.0), 20.0, 50.0, np.ones((2, 21), bool)) == pytest.approx(expected)


def test_shapes_are_checked():
    # the functions' own checks: unwrapped, since in the test run the annotations' check refuses the shapes first
    with pytest.raises(ValueError, match="pred, gt"):
        inspect.unwrap(mpjpe)(np.zeros((2, 21, 3)), np.zeros((2, 20, 3)), np.ones((2, 21), bool))
    with pytest.raises(ValueError, match="mask"):
        inspect.unwrap(mpjpe)(np.zeros((2, 21, 3)), np.zeros((2, 21, 3)), np.ones(21, bool))
    with pytest.raises(ValueError, match="lo, hi"):
        pck_auc(np.zeros((1, 21)), 50.0, 20.0, np.ones((1, 21), bool))
