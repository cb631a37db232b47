"""Identities across frames on synthetic people: crossing paths, entering and leaving, hidden for a while."""

import numpy as np

from jaxmocap.detect.assignment import gated_pairs
from jaxmocap.detect.identities import IdentityTracker

SKELETON = np.random.default_rng(0).uniform([-40, -90], [40, 90], (33, 2))  # a person 180 px tall about its centre
LOOKS = np.eye(2, 72, dtype=np.float32)[:, ::-1] * 0.5 + np.eye(2, 72, 5, dtype=np.float32) * 0.5  # two outfits


def person(rng, centre, jitter=2.0):
    return np.concatenate([SKELETON + centre + rng.normal(0, jitter, (33, 2)), np.ones((33, 1))], axis=1)


def frame_ids(tracker, rng, centres, looks):
    """Ids the tracker gives the people at ``centres``, shown in a shuffled order (as a detector may); ``rng``
    (each test's own) jitters and shuffles them."""
    order = rng.permutation(len(centres))
    landmarks = np.stack([person(rng, centres[k]) for k in order]) if len(order) else np.zeros((0, 33, 3))
    ids = tracker(landmarks, np.asarray(looks)[order] if len(order) else np.zeros((0, 72)))
    return [ids[list(order).index(k)] for k in range(len(centres))]


def test_two_people_crossing_keep_their_ids():
    """Two people of the same size walk through each other at the same height in the image, 3 px a frame each
    way (they pass 3 px apart): no swap, with or without telling their clothes apart."""
    rng = np.random.default_rng(1)
    for looks in (LOOKS, np.zeros((2, 72), np.float32)):
        tracker = IdentityTracker()
        seen = [frame_ids(tracker, rng, [(100 + 3 * t, 300), (505 - 3 * t, 300)], looks) for t in range(135)]
        assert sorted(seen[0]) == [0, 1] and all(ids == seen[0] for ids in seen), looks.any()


def test_a_person_hidden_behind_another_is_reidentified():
    """The second person is hidden for 20 frames while passing behind the first; they come back as themselves,
    and someone entering later gets a new id."""
    tracker, rng = IdentityTracker(), np.random.default_rng(2)
    frame_ids(tracker, rng, [(300, 300)], LOOKS[:1])
    for t in range(1, 60):
        hidden = 20 <= t < 40
        centres = [(300, 300)] + ([] if hidden else [(100 + 5 * t, 320)])
        ids = frame_ids(tracker, rng, centres, LOOKS[:len(centres)])
        assert ids == ([0] if hidden else [0, 1])
    ids = frame_ids(tracker, rng, [(300, 300), (400, 320), (900, 300)], np.concatenate([LOOKS, LOOKS[:1]]))
    assert ids == [0, 1, 2]


def test_a_person_who_left_long_ago_is_someone_new():
    tracker, rng = IdentityTracker(max_gap=10), np.random.default_rng(3)
    assert frame_ids(tracker, rng, [(100, 100)], LOOKS[:1]) == [0]
    for _ in range(11):
        assert frame_ids(tracker, rng, [], []) == []
    assert frame_ids(tracker, rng, [(100, 100)], LOOKS[:1]) == [1]


def test_state_carries_the_tracks_over():
    """A tracker restored from another's state continues exactly as the original does."""
    original, restored, rng = IdentityTracker(), IdentityTracker(), np.random.default_rng(4)
    first = frame_ids(original, rng, [(100, 300), (500, 310)], LOOKS)
    for t in range(1, 10):
        frame_ids(original, rng, [(100 + 4 * t, 300), (500 - 4 * t, 310)], LOOKS)
    restored.restore({k: v.copy() for k, v in original.state().items()})
    centres, looks = [(140, 300), (460, 310), (800, 300)], np.concatenate([LOOKS, LOOKS[:1]])
    a = frame_ids(original, np.random.default_rng(5), centres, looks)
    b = frame_ids(restored, np.random.default_rng(5), centres, looks)
    assert a == b == first + [2]
    for key, value in original.state().items():
        np.testing.assert_array_equal(value, restored.state()[key], err_msg=key)


def test_a_person_the_detector_follows_keeps_their_id_however_the_landmarks_jump():
    """A person cut by the frame's edge whom the landmark model lays down in one frame and stands up in the next
    (their landmarks jump by a body's length): the same detector track keeps the id; told nothing of the detector's
    tracks, the tracker takes the lying one for someone new."""
    rng = np.random.default_rng(6)
    standing = person(rng, (300, 300))
    lying = np.concatenate([standing[:, [1, 0]] + (150, 0), standing[:, 2:]], axis=1)  # 180 px wide, 80 high
    for sources, expected in (([7], [0, 0, 0]), (None, [0, 1, 0])):
        tracker = IdentityTracker()
        ids = [tracker(lm[None], LOOKS[:1], sources)[0] for lm in (standing, lying, standing)]
        assert ids == expected, sources


def test_a_track_is_as_large_as_its_person_lying_or_standing():
    """The gate scales with the person's larger side: lying down (180 px wide, 80 high), a person who shifts by
    10 px a frame this way and that is the same person (a third of the gate by their height)."""
    rng = np.random.default_rng(7)
    lying = person(rng, (300, 300))[:, [1, 0, 2]]
    tracker = IdentityTracker()
    ids = [tracker((lying + (10 * (-1) ** t, 10 * (-1) ** (t // 2), 0))[None], LOOKS[:1])[0] for t in range(10)]
    assert ids == [0] * 10


def test_people_who_step_the_same_way_both_keep_their_ids():
    """Two people 50 px apart both step left, 45 and 30 px: the second lands nearest the first's old place. The
    pairing that keeps both (each within its gate) wins over the single nearest pair, which would leave the first
    person unmatched and new."""
    tracker, rng = IdentityTracker(), np.random.default_rng(7)
    blank = np.zeros((2, 72), np.float32)
    assert frame_ids(tracker, rng, [(300, 300), (350, 300)], blank) == [0, 1]
    assert frame_ids(tracker, rng, [(255, 300), (320, 300)], blank) == [0, 1]


def test_gated_pairs_pair_the_most_then_the_cheapest():
    inf = np.inf
    assert gated_pairs(np.array([[0.1, 0.2], [0.25, inf]])) == [(0, 1), (1, 0)]
    assert gated_pairs(np.array([[0.1, 0.2], [0.3, 0.1]])) == [(0, 0), (1, 1)]
    assert gated_pairs(np.array([[inf, inf], [inf, 5.0]])) == [(1, 1)]
    assert gated_pairs(np.full((2, 3), inf)) == [] and gated_pairs(np.zeros((0, 2))) == []
