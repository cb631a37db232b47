"""Per-frame observations of the tracked person from the detector, as fixed-shape arrays."""

import dataclasses
from dataclasses import dataclass

import numpy as np

from jaxmocap.detect import Detector, to_openpose
from jaxmocap.detect.openpose import LEFT_HAND_SLICE, RIGHT_HAND_SLICE


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


def fill_hand_gaps(obs: Observations, max_gap: int) -> Observations:
    """Each hand lost for at most ``max_gap`` frames between two frames that have it (the person found throughout)
    interpolated linearly: its 2D keypoints (those seen at both ends), 3D landmarks, presence and box."""
    keypoints, hands_world = obs.keypoints.copy(), obs.hands_world.copy()
    hands_conf, hand_boxes = obs.hands_conf.copy(), obs.hand_boxes.copy()
    for side, part in enumerate((LEFT_HAND_SLICE, RIGHT_HAND_SLICE)):
        seen = np.flatnonzero(obs.hands_conf[:, side] > 0)
        for a, b in zip(seen[:-1], seen[1:]):
            if not 1 < b - a <= max_gap + 1 or not obs.found[a:b].all():
                continue
            later = (np.arange(a + 1, b) - a) / (b - a)  # the weight of frame b

            def lerp(x):
                w = later.reshape((-1,) + (1,) * (x.ndim - 1))
                return (1 - w) * x[a] + w * x[b]

            both = (obs.keypoints[a, part, 2] > 0) & (obs.keypoints[b, part, 2] > 0)
            keypoints[a + 1:b, part] = lerp(obs.keypoints[:, part]) * both[None, :, None]
            hands_world[a + 1:b, side] = lerp(obs.hands_world[:, side])
            hands_conf[a + 1:b, side] = lerp(obs.hands_conf[:, side])
            hand_boxes[a + 1:b, side] = lerp(obs.hand_boxes[:, side])
    return dataclasses.replace(obs, keypoints=keypoints, hands_world=hands_world, hands_conf=hands_conf,
                               hand_boxes=hand_boxes)
