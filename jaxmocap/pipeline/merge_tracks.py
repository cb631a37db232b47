"""One identity per person over a whole video: tracks the identities split apart, joined again.

The tracker gives a person a new identity when it loses them for longer than it waits (turning round, leaving the
crop, a landmark drop-out). Offline, the whole video is known: a track that starts after another has ended, within
`MAX_GAP_SECONDS`, where that one left off (its body box's centre within `MAX_JUMP` box heights, its height within
`MAX_SIZE_RATIO`) is the same person, and takes the earlier identity. With at most one person (``--max-people 1``)
every track is that person.
"""

import numpy as np

from jaxmocap.pipeline.tracks import Track, frames_where

MAX_GAP_SECONDS = 2.0
MAX_JUMP = 1.0  # box heights between where one track ends and the next begins
MAX_SIZE_RATIO = 1.5


def _frames(track: Track) -> np.ndarray:
    return np.flatnonzero(track.found)


def _centre_height(box: np.ndarray) -> tuple[np.ndarray, float]:
    return (box[:2] + box[2:]) / 2, float(box[3] - box[1])


def continues(earlier: Track, later: Track, fps: float) -> bool:
    """``later`` begins after ``earlier`` ends, soon after and where it left off."""
    before, after = _frames(earlier), _frames(later)
    if not len(before) or not len(after) or after[0] <= before[-1]:
        return False
    if (after[0] - before[-1]) / fps > MAX_GAP_SECONDS:
        return False
    (c0, h0), (c1, h1) = _centre_height(earlier.body_box[before[-1]]), _centre_height(later.body_box[after[0]])
    if not (np.all(np.isfinite(c0)) and np.all(np.isfinite(c1)) and h0 > 0 and h1 > 0):
        return False
    return bool(np.linalg.norm(c1 - c0) <= MAX_JUMP * max(h0, h1) and max(h0, h1) / min(h0, h1) <= MAX_SIZE_RATIO)


def joined(earlier: Track, later: Track) -> Track:
    """One track: ``later``'s frames where it found the person, ``earlier``'s elsewhere."""
    return frames_where(later.found, later, earlier)


def merge_split_tracks(tracks: dict[int, Track], fps: float | None, max_people: int) -> dict[int, Track]:
    """``tracks`` by identity with each split person joined under their first identity (`continues`, in order of
    first appearance); with ``max_people == 1`` all of them. ``fps`` None (images, not a video): as they are."""
    if fps is None or len(tracks) < 2:
        return tracks
    order = sorted((i for i in tracks if tracks[i].found.any()), key=lambda i: _frames(tracks[i])[0])
    merged = {i: t for i, t in tracks.items() if not t.found.any()}  # never found: nothing to join
    for i in order:
        target = next((j for j in merged if merged[j].found.any()
                       and (max_people == 1 or continues(merged[j], tracks[i], fps))), None)
        if target is None:
            merged[i] = tracks[i]
        else:
            merged[target] = joined(merged[target], tracks[i])
    return dict(sorted(merged.items()))
