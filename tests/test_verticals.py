"""The scene's vertical from its upright edges (`jaxmocap.detect.verticals`): poles and a floor's grid drawn as a
tilted, rolled camera sees them give the camera's up back, and its focal length; edges that lie flat are not
taken for the vertical."""

import cv2
import numpy as np
import pytest

from jaxmocap.detect.verticals import Segments, scene_vertical, vertical_direction
from smplx_jax import rotations

SIZE, FOCAL = (960, 720), 800.0
CENTRE = np.array([SIZE[0] / 2, SIZE[1] / 2])


def _camera(pitch_deg: float, roll_deg: float) -> np.ndarray:
    """World (y up) to camera (x right, y down, z forward): looking along the world's -z, down by ``pitch_deg``,
    rolled by ``roll_deg``."""
    pitch = np.asarray(rotations.rotvec_to_rotmat(np.array([np.pi + np.radians(pitch_deg), 0.0, 0.0])))
    roll = np.asarray(rotations.rotvec_to_rotmat(np.array([0.0, 0.0, np.radians(roll_deg)])))
    return roll @ pitch


def _drawn(rotation: np.ndarray, segments: np.ndarray) -> np.ndarray:
    """Segments ``(N, 2, 3)`` of the world (the camera 1.6 m above the floor) drawn as the camera sees them."""
    image = np.full((SIZE[1], SIZE[0]), 235, np.uint8)
    points = (segments - np.array([0.0, 1.6, 0.0])) @ rotation.T
    for a, b in points:
        if a[2] > 0.3 and b[2] > 0.3:
            pa, pb = (FOCAL * p[:2] / p[2] + CENTRE for p in (a, b))
            cv2.line(image, tuple(np.round(pa).astype(int)), tuple(np.round(pb).astype(int)), 20, 2, cv2.LINE_AA)
    return image


def _poles(rng, count=24) -> np.ndarray:
    """Upright edges 0.3-1.2 m tall standing 2-8 m ahead, spread across the view."""
    base = np.stack([rng.uniform(-3, 3, count), rng.uniform(0, 1.0, count), -rng.uniform(2, 8, count)], 1)
    return np.stack([base, base + np.array([0.0, 1.0, 0.0]) * rng.uniform(0.3, 1.2, (count, 1))], 1)


def _grid() -> np.ndarray:
    """A floor's grid lines, 0.5 m apart."""
    lines = [[[x, 0.0, -1.0], [x, 0.0, -9.0]] for x in np.arange(-3, 3.1, 0.5)]
    lines += [[[-3.0, 0.0, -z], [3.0, 0.0, -z]] for z in np.arange(1.0, 9.1, 0.5)]
    return np.asarray(lines)


@pytest.mark.parametrize("pitch, roll", [(20.0, 0.0), (25.0, 12.0), (5.0, -30.0)])
def test_upright_edges_give_the_up_direction(pitch, roll):
    rotation = _camera(pitch, roll)
    up = rotation[:, 1]
    image = _drawn(rotation, np.concatenate([_poles(np.random.default_rng(0)), _grid()]))
    near = _camera(pitch + 20.0, roll - 15.0)[:, 1]  # the body's lean: 25 degrees off
    segments = Segments.detect([image])
    found = vertical_direction(segments, FOCAL, CENTRE, near)
    assert found is not None
    assert np.degrees(np.arccos(np.clip(found @ up, -1, 1))) < 0.5
    # through a focal length 20% off, the vertical tilts; the scene's own (its level edges square to the upright
    # ones) puts it back
    guess = 0.8 * FOCAL
    found, focal = scene_vertical(segments, guess, CENTRE, near, max(SIZE))
    assert focal == pytest.approx(FOCAL, rel=0.04)
    tilted = vertical_direction(segments, guess, CENTRE, near)
    assert np.degrees(np.arccos(np.clip(found @ up, -1, 1))) < 0.5 < np.degrees(np.arccos(np.clip(tilted @ up, -1, 1)))
    held, _ = scene_vertical(segments, FOCAL, CENTRE, near, max(SIZE), fixed=True)  # the focal length given
    assert np.degrees(np.arccos(np.clip(held @ up, -1, 1))) < 0.5


def test_edges_that_lie_flat_are_not_the_vertical():
    """A floor's grid alone (its lines converge far from the up direction), or nothing: no vertical, no focal
    length."""
    rotation = _camera(25.0, 12.0)
    near = rotation[:, 1]
    for segments in (_grid(), np.zeros((0, 2, 3))):
        found = Segments.detect([_drawn(rotation, segments)])
        assert vertical_direction(found, FOCAL, CENTRE, near) is None
        assert scene_vertical(found, FOCAL, CENTRE, near, max(SIZE)) == (None, FOCAL)
