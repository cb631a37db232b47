"""Per-frame observations of each tracked person from the detector, as fixed-shape arrays, and their repairs."""

import dataclasses
from dataclasses import dataclass

import numpy as np

from jaxmocap.detect import Detector, Person, to_openpose
from jaxmocap.detect.identities import IdentityTracker, identify
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
    arrays = _no_one(len(frames))
    for i, frame in enumerate(frames):
        people = detector(frame)
        if people:
            _record(arrays, i, people[0])
    return Observations(**arrays)


def observe_people(detector: Detector, tracker: IdentityTracker | None, frames: list[np.ndarray]
                   ) -> dict[int, Observations]:
    """Each person's observations over the frames, by identity (`IdentityTracker`; without one, each frame's
    people numbered in the detector's order, as for unrelated images); zeros where a person is not seen."""
    people = {}
    for i, frame in enumerate(frames):
        found = detector(frame)
        for person_id, person in zip(identify(tracker, frame, found), found):
            _record(people.setdefault(person_id, _no_one(len(frames))), i, person)
    return {person_id: Observations(**arrays) for person_id, arrays in sorted(people.items())}


def _no_one(n: int) -> dict[str, np.ndarray]:
    return dict(keypoints=np.zeros((n, 67, 3)), body_world=np.zeros((n, 33, 4)), hands_world=np.zeros((n, 2, 21, 3)),
                hands_conf=np.zeros((n, 2)), body_box=np.full((n, 4), np.nan), hand_boxes=np.full((n, 2, 4), np.nan),
                found=np.zeros(n, bool))


def _record(arrays: dict[str, np.ndarray], i: int, person: Person) -> None:
    """Frame ``i`` of a person's arrays from the detector's `Person`, in place."""
    arrays["found"][i] = True
    arrays["keypoints"][i] = to_openpose([person])[0]
    arrays["body_world"][i] = np.concatenate([person.body_world, person.body[:, 3:4]], axis=1)
    arrays["body_box"][i] = person.box
    for side, (world, score, box) in enumerate((
            (person.left_hand_world, person.left_hand_score, person.left_hand_box),
            (person.right_hand_world, person.right_hand_score, person.right_hand_box))):
        if world is not None:
            arrays["hands_world"][i, side], arrays["hands_conf"][i, side] = world, score
            arrays["hand_boxes"][i, side] = box


# A hand lost for at most this long is interpolated (over a person's whole track before the clip fit; in each chunk
# for the regressors' crops): a blink of motion blur or occlusion, in which a hand moves on as it did.
HAND_GAP_SECONDS = 0.25


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


# Left/right pairs of each side group: (OpenPose BODY_25 pairs, BlazePose pairs); the arms' group carries the hands.
_ARMS = (((2, 5), (3, 6), (4, 7)), ((11, 12), (13, 14), (15, 16), (17, 18), (19, 20), (21, 22)))
_LEGS = (((9, 12), (10, 13), (11, 14), (19, 22), (20, 23), (21, 24)),
         ((23, 24), (25, 26), (27, 28), (29, 30), (31, 32)))


def _swap_sides(obs: Observations, t: int, group) -> None:
    """Exchange left and right of one side group in frame ``t``, in place."""
    openpose, blazepose = group
    for a, b in openpose:
        obs.keypoints[t, [a, b]] = obs.keypoints[t, [b, a]]
    for a, b in blazepose:
        obs.body_world[t, [a, b]] = obs.body_world[t, [b, a]]
    if group is _ARMS:
        obs.keypoints[t, 25:67] = np.roll(obs.keypoints[t, 25:67], 21, axis=0)
        for hands in (obs.hands_world, obs.hands_conf, obs.hand_boxes):
            hands[t] = hands[t, ::-1].copy()


def repair_side_swaps(obs: Observations, previous: np.ndarray | None = None, ratio: float = 0.5) -> Observations:
    """Arms (with hands) or legs whose left and right the detector exchanged, put back, frame after frame: where
    the limbs' 2D keypoints lie, with left and right exchanged, nearer the previous frame's (by ``ratio`` of the
    distance) than as detected, and farther than a tenth of the torso apart. A swap the detector keeps for many
    frames is repaired in all of them, as each is compared with its repaired predecessor; ``previous`` (67, 3) is the
    repaired keypoints of the frame before the first (None: the person was not there), so that frames repaired
    in chunks come out as repaired all at once."""
    obs = dataclasses.replace(obs, **{k: getattr(obs, k).copy() for k in (
        "keypoints", "body_world", "hands_world", "hands_conf", "hand_boxes")})
    there = np.concatenate([[previous is not None], obs.found[:-1]]) & obs.found
    for t in np.flatnonzero(there):
        now, before = obs.keypoints[t], obs.keypoints[t - 1] if t > 0 else previous
        torso = np.linalg.norm(now[1, :2] - now[8, :2]) if now[1, 2] > 0 and now[8, 2] > 0 else np.inf
        for group in (_ARMS, _LEGS):
            left, right = (list(side) for side in zip(*group[0]))
            seen = (now[left, 2] > 0) & (now[right, 2] > 0) & (before[left, 2] > 0) & (before[right, 2] > 0)
            if not seen.any():
                continue
            def distance(a, b):
                return np.linalg.norm(now[a, :2] - before[b, :2], axis=-1)[seen].mean()
            same = distance(left, left) + distance(right, right)
            swapped = distance(left, right) + distance(right, left)
            if swapped < ratio * same and same > 0.2 * torso:
                _swap_sides(obs, int(t), group)
    return obs
