"""Hand boxes from the body's projected hands (FrankMocap's fast mode) against ``BodyMocap.get_hand_bboxes``."""

import inspect

import jax
import numpy as np
import pytest

import smplx_jax
from jaxmocap.pipeline.hand_boxes import hand_boxes_from_body
from jaxmocap.poses import example_pose
from smplx_jax import constants

SIZE = (640, 480)


def reference_hand_bboxes(joints_img, img_shape):
    """``BodyMocap.get_hand_bboxes`` (bodymocap/body_mocap_api.py) for one body, transcribed; (x, y, w, h)."""
    boxes = []
    for ids in (constants.LEFT_HAND21_FROM_SMPLX, constants.RIGHT_HAND21_FROM_SMPLX):
        hand = joints_img[list(ids)]
        x0, x1 = np.min(hand[:, 0]), np.max(hand[:, 0])
        y0, y1 = np.min(hand[:, 1]), np.max(hand[:, 1])
        margin = int(max(y1 - y0, x1 - x0) * 0.2)
        img_height, img_width = img_shape
        x0, y0 = max(x0 - margin, 0), max(y0 - margin, 0)
        x1, y1 = min(x1 + margin, img_width), min(y1 + margin, img_height)
        boxes.append([x0, y0, x1 - x0, y1 - y0])
    return np.array(boxes)


@pytest.fixture(scope="module")
def projected(default_model_dir):
    """A posed body's 127 joints in pixels (weak perspective, docs/formats.md, "Coordinates and cameras"; y flipped
    by the global orientation), at three placements: centred, shifted so the right hand crosses the left edge, and
    missing (NaN)."""
    model = smplx_jax.load_model(default_model_dir / "smplx" / "SMPLX_NEUTRAL.npz")
    params = example_pose(model.num_betas, model.num_expression).replace(global_orient=np.array([np.pi, 0.0, 0.0]))
    joints = np.asarray(jax.jit(smplx_jax.forward_joints)(model, params))
    pixels = 200.0 * joints[:, :2] + np.array([320.0, 240.0])
    right_x = pixels[list(constants.RIGHT_HAND21_FROM_SMPLX), 0]
    shifted = pixels - np.array([right_x.min() + 10.0, 0.0])  # the right hand 10 px past the left edge
    return np.stack([pixels, shifted, np.full_like(pixels, np.nan)])


def test_boxes_enclose_the_projected_hands_with_frankmocaps_margin(projected):
    boxes = hand_boxes_from_body(projected, SIZE)
    assert boxes.shape == (3, 2, 4) and np.all(np.isnan(boxes[2]))
    for n in range(2):
        expected = reference_hand_bboxes(projected[n], SIZE[::-1])
        np.testing.assert_allclose(boxes[n, :, :2], expected[:, :2], atol=1e-9)
        np.testing.assert_allclose(boxes[n, :, 2:] - boxes[n, :, :2], expected[:, 2:], atol=1e-9)
        for side, ids in enumerate((constants.LEFT_HAND21_FROM_SMPLX, constants.RIGHT_HAND21_FROM_SMPLX)):
            hand = projected[n, list(ids)]
            inside = np.clip(hand, 0, SIZE)
            assert np.all(inside >= boxes[n, side, :2]) and np.all(inside <= boxes[n, side, 2:])
            assert np.all(boxes[n, side, :2] >= 0) and np.all(boxes[n, side, 2:] <= SIZE)
    assert boxes[0, 1, 0] > 0 and boxes[1, 1, 0] == 0  # the shifted body's hand is clipped at the left edge
    margin = boxes[0, 0, :2] - projected[0, list(constants.LEFT_HAND21_FROM_SMPLX)].min(axis=0)
    assert np.all(margin < 0) and np.all(margin == np.trunc(margin))


def test_bad_shape_is_refused():
    # the function's own check: unwrapped, since in the test run the annotation's check refuses the shape first
    with pytest.raises(ValueError, match="joints_2d"):
        inspect.unwrap(hand_boxes_from_body)(np.zeros((2, 67, 2)), SIZE)
