"""People who overlap (issue 70): two people told apart by their skeletons, not by their boxes, and each of two
overlapping people tracked through stand-ins made from the shipped clips (`bench.stand_ins`), as ``jaxmocap run``
tracks them (the detector and the identities)."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from bench.stand_ins import body25, followed, near_crop, pasted, read, tracked
from jaxmocap.detect import Detector
from jaxmocap.detect.detector import SAME_SKELETON, SIDES_EXCHANGED, _coincide, skeleton_gap
from jaxmocap.detect.pose import PoseResult, rect_iou
from jaxmocap.detect.roi import Rect

DATA = Path(__file__).parent / "data"
FRAMES = 30  # the pasted stand-in's first frames: the two people overlap in them


@pytest.fixture(scope="module")
def skeleton():
    """A real person's BlazePose skeleton: (33, 4) pixels and visibility, and the image's size."""
    image = cv2.imread(str(DATA / "pose2sim_cam01_f000.jpg"))
    person = Detector(static_image_mode=True, hands=False)(image)[0]
    return person.body[:, [0, 1, 2, 3]], (image.shape[1], image.shape[0])


def _pose(body: np.ndarray, size) -> PoseResult:
    """A `PoseResult` of a (33, 4) pixel skeleton, its ROIs the square around it."""
    normalized = np.concatenate([body[:, :3] / (*size, size[0]), body[:, 3:], np.ones((33, 1))], axis=1)
    (x0, y0), (x1, y1) = body[:, :2].min(0), body[:, :2].max(0)
    side = 1.25 * max(x1 - x0, y1 - y0)
    roi = Rect((x0 + x1) / 2 / size[0], (y0 + y1) / 2 / size[1], side / size[0], side / size[1])
    return PoseResult(normalized, np.zeros((33, 3)), 1.0, roi, roi)


def test_two_people_side_by_side_are_two_though_their_boxes_overlap(skeleton):
    body, size = skeleton
    torso = np.linalg.norm(body[[11, 12], :2].mean(0) - body[[23, 24], :2].mean(0))
    one, beside = _pose(body, size), _pose(body + [0.6 * torso, 0, 0, 0], size)
    assert rect_iou(one.next_roi, beside.next_roi) > 0.5  # the rule of boxes took them for one
    assert skeleton_gap(beside, one, size) == pytest.approx(0.6, abs=0.01)
    assert not _coincide(beside, one, size) and not _coincide(one, beside, size)


def test_one_person_seen_twice_is_one_whichever_side_the_model_calls_left(skeleton):
    body, size = skeleton
    torso = np.linalg.norm(body[[11, 12], :2].mean(0) - body[[23, 24], :2].mean(0))
    noise = np.random.default_rng(0).normal(0, 0.03 * torso, (33, 2))
    again = body.copy()
    again[:, :2] += noise
    exchanged = again[SIDES_EXCHANGED]
    for other in (again, exchanged):
        assert skeleton_gap(_pose(other, size), _pose(body, size), size) < SAME_SKELETON / 2
        assert _coincide(_pose(other, size), _pose(body, size), size)


def _tracked_by_identity(video: Path) -> dict[int, np.ndarray]:
    """Each identity's BODY_25 keypoints (T, 25, 3) through a video, tracked as ``jaxmocap run --max-people 2``."""
    frames, fps = read(video)
    return {k: body25(points) for k, points in enumerate(tracked(frames, fps, 2))}


def test_two_people_each_tracked_where_the_one_in_front_fills_the_frame(tmp_path):
    """The two-person take cropped around the person in front (the other passes behind them, cut by the crop's
    top): each person is followed in at least 95% of the frames where half of them can be seen, by one identity,
    and no identity goes to both."""
    truth = near_crop(DATA / "pose2sim_multi_cam01.mp4", tmp_path / "near.mp4")
    assert truth.seen.sum(1).min() >= 90  # both people are there to be found
    result = followed(_tracked_by_identity(tmp_path / "near.mp4"), truth)
    for person in result["people"]:
        assert person["tracked"] >= 0.95 * person["seen"] and len(person["by"]) == 1, result
    assert not result["on_both"], result


def test_a_person_pasted_in_front_is_kept_and_the_one_behind_found(tmp_path):
    """A copy of the single-person take's person pasted in front of them (its first frames): the person in front
    is followed in at least 95% of the frames by one identity; the one behind, half hidden, is found too (in a
    third of the frames where half of them can be seen, at least), and no identity goes to both."""
    video = Path(__file__).parents[1] / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"
    truth = pasted(video, tmp_path / "pasted.mp4", True, FRAMES)
    behind, front = followed(_tracked_by_identity(tmp_path / "pasted.mp4"), truth)["people"]
    assert front["tracked"] >= 0.95 * front["seen"] and len(front["by"]) == 1, front
    assert behind["tracked"] >= behind["seen"] / 3, behind
    assert not set(front["by"]) & set(behind["by"]), (front, behind)
