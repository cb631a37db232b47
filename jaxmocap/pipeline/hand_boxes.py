"""Hand boxes from the body regressor's projected hands (FrankMocap's ``--frankmocap_fast_mode``), so the hand
detector can be skipped."""

import numpy as np
from jaxtyping import Float

from smplx_jax import constants

MARGIN = 0.2  # of the longer side, each side (``BodyMocap.get_hand_bboxes``)
HAND_JOINTS = np.asarray(constants.OPENPOSE67_FROM_SMPLX[25:]).reshape(2, 21)  # left, right: wrist + 20 finger joints


def hand_boxes_from_body(joints_2d: Float[np.ndarray, "N 127 2"], image_size: tuple[int, int]
                         ) -> Float[np.ndarray, "N 2 4"]:
    """Left and right hand boxes (x0, y0, x1, y1) as FrankMocap's ``BodyMocap.get_hand_bboxes`` makes them from
    the projected SMPL-X hand joints (smplx joint order, image pixels): their extent grown by ``int(0.2 *
    longer side)`` each side, clipped to the image (``image_size`` = width, height). NaN rows stay NaN."""
    joints_2d = np.asarray(joints_2d, np.float64)
    if joints_2d.ndim != 3 or joints_2d.shape[1:] != (constants.NUM_OUTPUT_JOINTS, 2):
        raise ValueError(f"joints_2d: expected (N, {constants.NUM_OUTPUT_JOINTS}, 2), got shape {joints_2d.shape}")
    hands = joints_2d[:, HAND_JOINTS]  # N, 2, 21, 2
    lo, hi = hands.min(axis=2), hands.max(axis=2)
    margin = np.trunc(MARGIN * (hi - lo).max(axis=-1, keepdims=True))
    return np.concatenate([np.maximum(lo - margin, 0), np.minimum(hi + margin, image_size)], axis=-1)
