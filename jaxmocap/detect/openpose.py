"""OpenPose keypoints: BODY_25 + two 21-point hands from mediapipe landmarks, and OpenPose JSON files.

Layout of the (67, 3) array per person: BODY_25 (0-24), left hand (25-45), right hand (46-66), each row x, y in
pixels and a confidence; a missing point is (0, 0, 0). mediapipe's 21 hand landmarks are already in OpenPose's
hand order.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from smplx_jax.atomic_files import atomic_write_text

NUM_KEYPOINTS = 67
BODY_SLICE, LEFT_HAND_SLICE, RIGHT_HAND_SLICE = slice(0, 25), slice(25, 46), slice(46, 67)

# BODY_25 index -> BlazePose landmark(s); a pair is averaged (neck, mid-hip); None = not available (small toes).
BODY25_FROM_BLAZEPOSE: list[tuple[int, ...] | None] = [
    (0,), (11, 12), (12,), (14,), (16,), (11,), (13,), (15,), (23, 24), (24,), (26,), (28,), (23,), (25,), (27,),
    (5,), (2,), (8,), (7,), (31,), None, (29,), (32,), None, (30,),
]


def body25_from_blazepose(body: np.ndarray) -> np.ndarray:
    """(25, 3) BODY_25 from (33, >=4) BlazePose landmarks in pixels (x, y, z, visibility); confidence = visibility
    (the smaller of the two for neck and mid-hip)."""
    out = np.zeros((25, 3))
    for j, src in enumerate(BODY25_FROM_BLAZEPOSE):
        if src is None:
            continue
        pts = body[list(src)]
        out[j, :2] = pts[:, :2].mean(0)
        out[j, 2] = pts[:, 3].min()
    return out


def hand21(hand: np.ndarray | None, confidence: float) -> np.ndarray:
    """(21, 3) OpenPose hand from (21, >=2) pixel landmarks (zeros when the hand is missing)."""
    out = np.zeros((21, 3))
    if hand is not None:
        out[:, :2] = hand[:, :2]
        out[:, 2] = confidence
    return out


def write_openpose_json(path: str | os.PathLike, keypoints: np.ndarray, person_ids=None, body: bool = True) -> Path:
    """Write (P, 67, 3) keypoints as one OpenPose 1.3 JSON file, atomically, each person with the ``person_id``
    OpenPose's tracker writes (``[id]``; ``[-1]`` untracked, as OpenPose without its tracker); without ``body``
    hands only, ``"pose_keypoints_2d": []`` as OpenPose writes it with ``--body 0``. Returns the path."""
    keypoints = np.asarray(keypoints, dtype=np.float64)
    if keypoints.ndim != 3 or keypoints.shape[1:] != (NUM_KEYPOINTS, 3):
        raise ValueError(f"keypoints must have shape (num_people, 67, 3), got {keypoints.shape}")
    person_ids = [-1] * len(keypoints) if person_ids is None else [int(i) for i in person_ids]
    if len(person_ids) != len(keypoints):
        raise ValueError(f"{len(person_ids)} person ids for {len(keypoints)} people")
    people = [{
        "person_id": [person_id],
        "pose_keypoints_2d": _flat(p[BODY_SLICE]) if body else [],
        "hand_left_keypoints_2d": _flat(p[LEFT_HAND_SLICE]),
        "hand_right_keypoints_2d": _flat(p[RIGHT_HAND_SLICE]),
        "face_keypoints_2d": [],
    } for p, person_id in zip(keypoints, person_ids)]
    return atomic_write_text(path, json.dumps({"version": 1.3, "people": people}, separators=(",", ":")))


def _flat(a: np.ndarray) -> list[float]:
    return [round(float(v), 3) for v in a.reshape(-1)]


def _part(person: dict, key: str, count: int, path) -> np.ndarray:
    values = person.get(key) or []
    if len(values) == 0:
        return np.zeros((count, 3))
    if len(values) != count * 3:
        raise ValueError(f"{path}: '{key}' has {len(values)} values, expected {count * 3} "
                         f"({'BODY_25' if count == 25 else 'a 21-point hand'})")
    return np.asarray(values, dtype=np.float64).reshape(count, 3)


def read_openpose_json(path: str | os.PathLike) -> np.ndarray:
    """(P, 67, 3) keypoints from an OpenPose JSON file (BODY_25, left hand, right hand; missing parts are zeros).

    Accepts what OpenPose writes: extra keys (``person_id``, ``*_3d``, face), empty ``people``, absent hands.
    """
    try:
        with open(path) as f:
            data = json.load(f)
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"cannot read OpenPose JSON {path}: {e}") from None
    if not isinstance(data, dict) or not isinstance(data.get("people", []), list):
        raise ValueError(f"{path}: not an OpenPose keypoint file (no 'people' list)")
    out = np.zeros((len(data.get("people", [])), NUM_KEYPOINTS, 3))
    for i, person in enumerate(data.get("people", [])):
        out[i, BODY_SLICE] = _part(person, "pose_keypoints_2d", 25, path)
        out[i, LEFT_HAND_SLICE] = _part(person, "hand_left_keypoints_2d", 21, path)
        out[i, RIGHT_HAND_SLICE] = _part(person, "hand_right_keypoints_2d", 21, path)
    return out


def json_name(stem: str, frame: int | None) -> str:
    """``<stem>_<frame:012d>_keypoints.json`` for a video frame, ``<stem>_keypoints.json`` for an image."""
    return f"{stem}_keypoints.json" if frame is None else f"{stem}_{frame:012d}_keypoints.json"
