"""Per-frame observations of the tracked person from the detector, as fixed-shape arrays."""

from dataclasses import dataclass

import numpy as np

from jaxmocap.detect import Detector, to_openpose


@dataclass(frozen=True)
class Observations:
    """``N`` frames. Missing data are zeros with zero confidence."""

    keypoints: np.ndarray  # (N, 67, 3) OpenPose BODY_25 + left hand + right hand, pixels, confidence
    body_world: np.ndarray  # (N, 33, 4) BlazePose world landmarks (metres) and visibility
    hands_world: np.ndarray  # (N, 2, 21, 3) left, right hand world landmarks (metres)
    hands_conf: np.ndarray  # (N, 2) hand presence, 0 when missing
    body_box: np.ndarray  # (N, 4) x0, y0, x1, y1 pixels, NaN when missing
    hand_boxes: np.ndarray  # (N, 2, 4) left, right, NaN when missing
    found: np.ndarray  # (N,) bool: a person was detected


def observe(detector: Detector, frames: list[np.ndarray]) -> Observations:
    """Detect the (first) person in each frame; the detector tracks across the given frames."""
    n = len(frames)
    keypoints, body_world = np.zeros((n, 67, 3)), np.zeros((n, 33, 4))
    hands_world, hands_conf, found = np.zeros((n, 2, 21, 3)), np.zeros((n, 2)), np.zeros(n, bool)
    body_box, hand_boxes = np.full((n, 4), np.nan), np.full((n, 2, 4), np.nan)
    for i, frame in enumerate(frames):
        people = detector(frame)
        if not people:
            continue
        person = people[0]
        found[i] = True
        keypoints[i] = to_openpose([person])[0]
        body_world[i] = np.concatenate([person.body_world, person.body[:, 3:4]], axis=1)
        body_box[i] = person.box
        for side, (world, score, box) in enumerate((
                (person.left_hand_world, person.left_hand_score, person.left_hand_box),
                (person.right_hand_world, person.right_hand_score, person.right_hand_box))):
            if world is not None:
                hands_world[i, side], hands_conf[i, side], hand_boxes[i, side] = world, score, box
    return Observations(keypoints, body_world, hands_world, hands_conf, body_box, hand_boxes, found)
