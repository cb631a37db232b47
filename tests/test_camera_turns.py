"""`jaxmocap.detect.camera_turns`: a real frame of the lab seen by a camera that turns about its centre (each view
warped from a larger frame through the lens), held still, and travelling; the turns carried across chunks."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from jaxmocap.detect.camera_turns import CameraTurns, background_mask, camera_motion

SCENE = cv2.imread(str(Path(__file__).parent / "data" / "pose2sim_cam01_f000.jpg"))  # 540 x 960
FOCAL = 720.0
SIZE = (360, 640)  # the camera's frames (width, height), a window of the scene's
CENTRE = np.asarray(SIZE, np.float64) / 2
LENS = (FOCAL, CENTRE)


def _matrix(centre) -> np.ndarray:
    return np.array([[FOCAL, 0.0, centre[0]], [0.0, FOCAL, centre[1]], [0.0, 0.0, 1.0]])


def seen(turn: np.ndarray) -> np.ndarray:
    """What a camera turned by ``turn`` (its axes into the scene's, axis-angle) sees: each scene ray ``d`` at
    ``R^T d`` in its axes."""
    rotation = cv2.Rodrigues(np.asarray(turn, np.float64))[0]
    scene_centre = np.asarray(SCENE.shape[1::-1], np.float64) / 2
    homography = _matrix(CENTRE) @ rotation.T @ np.linalg.inv(_matrix(scene_centre))
    return cv2.warpPerspective(SCENE, homography, SIZE, flags=cv2.INTER_LINEAR)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angles between the rotations of two sequences of axis-angles."""
    return np.asarray([np.degrees(np.linalg.norm(cv2.Rodrigues(cv2.Rodrigues(x)[0].T @ cv2.Rodrigues(y)[0])[0]))
                       for x, y in zip(np.asarray(a, np.float64), np.asarray(b, np.float64))])


def _panning(frames: int = 30) -> np.ndarray:
    """A pan to 6 degrees with a tilt and a roll of a couple."""
    s = np.linspace(0.0, 1.0, frames)
    return np.radians(np.stack([2.5 * np.sin(3 * s), 6.0 * s, 1.5 * s], 1))


NO_ONE = [np.zeros((0, 4))]


def test_a_turning_camera_is_followed_to_a_twentieth_of_a_degree():
    truth = _panning()
    turns, stray = CameraTurns(LENS).turns([seen(t) for t in truth], NO_ONE * len(truth))
    assert _angle_deg(turns, truth).max() < 0.05
    assert np.nanmedian(stray) < 0.5
    assert "travel" not in camera_motion(turns, stray, max(SIZE))


def test_a_still_camera_does_not_turn():
    rng = np.random.default_rng(0)
    frame = seen(np.zeros(3))
    frames = [np.clip(frame + rng.normal(scale=2.0, size=frame.shape), 0, 255).astype(np.uint8) for _ in range(20)]
    turns, _ = CameraTurns(LENS).turns(frames, NO_ONE * len(frames))
    assert np.degrees(np.linalg.norm(turns, axis=1)).max() < 0.01


def test_a_run_resumed_between_chunks_turns_as_an_uninterrupted_one():
    truth = _panning()
    frames = [seen(t) for t in truth]
    whole, _ = CameraTurns(LENS).turns(frames, NO_ONE * len(frames))
    first = CameraTurns(LENS)
    before, _ = first.turns(frames[:13], NO_ONE * 13)
    resumed = CameraTurns(LENS)
    resumed.restore(first.state())
    after, _ = resumed.turns(frames[13:], NO_ONE * (len(frames) - 13))
    np.testing.assert_array_equal(np.concatenate([before, after]), whole)


def test_a_person_moving_across_the_frame_does_not_turn_it():
    """A textured patch (a person) sweeping across a still camera's frame, inside its box: no turn."""
    frame = seen(np.zeros(3))
    patch = cv2.resize(SCENE[100:400, 50:200], (120, 240))
    frames, boxes = [], []
    for k in range(20):
        image = frame.copy()
        x = 20 + 10 * k
        image[200:440, x:x + 120] = patch
        frames.append(image)
        boxes.append(np.array([[x, 200, x + 120, 440]], np.float64))
    turns, _ = CameraTurns(LENS).turns(frames, boxes)
    assert np.degrees(np.linalg.norm(turns, axis=1)).max() < 0.02


def test_a_travelling_camera_is_reported():
    """Three depths of the scene moving apart (a camera that travels sideways): no one turn explains them."""
    frames = []
    for k in range(20):
        image = seen(np.zeros(3))
        for band, speed in enumerate((0.5, 2.0, 4.0)):
            rows = slice(band * SIZE[1] // 3, (band + 1) * SIZE[1] // 3)
            image[rows] = cv2.warpAffine(image[rows], np.float64([[1, 0, speed * k], [0, 1, 0]]),
                                         (SIZE[0], image[rows].shape[0]), borderMode=cv2.BORDER_REFLECT)
        frames.append(image)
    turns, stray = CameraTurns(LENS).turns(frames, NO_ONE * len(frames))
    assert "travel" in camera_motion(turns, stray, max(SIZE))


@pytest.mark.parametrize("box", [[100.0, 200.0, 200.0, 400.0], [np.nan] * 4])
def test_the_background_leaves_out_each_persons_widened_box(box):
    mask = background_mask((640, 360), np.array([box]), 0.5)
    if np.isnan(box[0]):
        assert mask.min() == 255
    else:  # (100..200, 200..400) widened by a fifth: (80..220, 160..440), at half size
        assert mask[80:220, 40:110].max() == 0 and mask[79, 60] == 255 and mask[150, 111] == 255
