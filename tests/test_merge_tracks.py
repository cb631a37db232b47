"""Offline, one identity per person: tracks split apart by the tracker are joined where one continues another."""

import dataclasses
from types import SimpleNamespace

import numpy as np

from jaxmocap.pipeline.merge_tracks import merge_split_tracks
from jaxmocap.pipeline.tracks import Track

FPS = 30.0
SIZES = SimpleNamespace(num_betas=10, num_expression=10)


def _track(frames, box, frame_count=60):
    """A person found in ``frames`` at ``box`` (x0, y0, x1, y1), their fit's camera scale the first frame's."""
    track = Track.absent(frame_count, SIZES)
    found = np.zeros(frame_count, bool)
    found[list(frames)] = True
    boxes = np.where(found[:, None], np.asarray(box, float), np.nan)
    scale = np.where(found, float(frames[0] + 1), 1.0).astype(np.float32)
    return dataclasses.replace(track, found=found, body_box=boxes,
                               bodies=dataclasses.replace(track.bodies, camera_scale=scale, valid=found))


def test_a_track_that_continues_another_takes_its_identity():
    first, second = _track(range(0, 20), (100, 100, 200, 400)), _track(range(25, 60), (130, 110, 225, 400))
    merged = merge_split_tracks({3: first, 7: second}, FPS, max_people=4)
    assert list(merged) == [3]
    one = merged[3]
    assert one.found.sum() == 55 and one.bodies.valid.sum() == 55
    np.testing.assert_array_equal(one.bodies.camera_scale[[0, 19, 25, 59]], [1, 1, 26, 26])  # each part its own


def test_other_people_keep_their_identities():
    person = _track(range(0, 20), (100, 100, 200, 400))
    tracks = {0: person,
              1: _track(range(25, 60), (600, 100, 700, 400)),  # elsewhere in the image
              2: _track(range(25, 60), (110, 100, 160, 200)),  # half the size: someone farther away
              3: _track(range(10, 60), (100, 100, 200, 400)),  # seen in the same frames: two people
              4: _track(range(150, 180), (100, 100, 200, 400), 180)}  # 3 s after the last of 0 and 3
    tracks = {i: t if i == 4 else _pad(t, 180) for i, t in tracks.items()}
    assert list(merge_split_tracks(tracks, FPS, max_people=4)) == [0, 1, 2, 3, 4]
    assert list(merge_split_tracks(tracks, None, max_people=4)) == [0, 1, 2, 3, 4]  # images: no time


def test_at_most_one_person_is_one_identity():
    tracks = {2: _track(range(30, 60), (600, 100, 700, 400)), 5: _track(range(0, 10), (100, 100, 200, 400))}
    merged = merge_split_tracks(tracks, FPS, max_people=1)
    assert list(merged) == [5] and merged[5].found.sum() == 40


def _pad(track, frame_count):
    extra = Track.absent(frame_count - len(track.found), SIZES)
    return Track.concatenate([track, extra])
