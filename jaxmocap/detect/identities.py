"""Stable identities for the people of a video. Each frame's people are matched to the tracks of the frames before
by the detector's own tracking (a person it followed from the previous frame keeps their identity), else by where
their body landmarks are expected (a constant-velocity model of each track) and by how they look (a colour
histogram of the torso); a track unseen for up to ``max_gap`` frames is kept, predicted forward, to be
re-identified when its person comes back. Ids are 0-based in order of first appearance."""

import dataclasses
from dataclasses import dataclass

import cv2
import numpy as np

from .assignment import gated_pairs

TORSO = (11, 12, 23, 24)  # BlazePose shoulders and hips
HISTOGRAM_BINS = (12, 6)  # hue, saturation
APPEARANCE_SIZE = HISTOGRAM_BINS[0] * HISTOGRAM_BINS[1]
MIN_VISIBILITY = 0.5


@dataclass(frozen=True)
class Track:
    """One identity: its body landmarks where last seen (pixels, visibility), the velocity of their centre
    (pixels per frame), the person's size (`_size`, pixels), the torso's colour histogram, the frame last seen, how
    many frames it was seen in, and the detector's track it was last seen as (`Person.track`, -1 unknown)."""

    id: int
    landmarks: np.ndarray  # (K, 3) x, y, visibility
    velocity: np.ndarray  # (2,)
    size: float
    appearance: np.ndarray  # (D,) L1-normalised histogram, zeros when unknown
    last_seen: int
    seen: int
    source: int = -1


def appearance(image: np.ndarray, landmarks: np.ndarray) -> np.ndarray:
    """The hue-saturation histogram (L1-normalised, flattened) of the box spanned by the torso landmarks of a BGR
    image, shrunk by a fifth towards its centre; zeros when the torso is not in the image."""
    h, w = image.shape[:2]
    torso = landmarks[list(TORSO), :2]
    centre, half = torso.mean(0), (torso.max(0) - torso.min(0)) * 0.4
    x0, y0 = np.clip(np.floor(centre - half), 0, (w, h)).astype(int)
    x1, y1 = np.clip(np.ceil(centre + half), 0, (w, h)).astype(int)
    if x1 - x0 < 2 or y1 - y0 < 2:
        return np.zeros(APPEARANCE_SIZE, np.float32)
    hsv = cv2.cvtColor(image[y0:y1, x0:x1], cv2.COLOR_BGR2HSV)
    hist = cv2.calcHist([hsv], [0, 1], None, list(HISTOGRAM_BINS), [0, 180, 0, 256]).ravel()
    return (hist / max(hist.sum(), 1.0)).astype(np.float32)


def identify(tracker: "IdentityTracker | None", image: np.ndarray, people: list) -> list[int]:
    """Identities of the detector's people (`jaxmocap.detect.Person`) in one BGR frame: the tracker's, or without
    one their order in the frame."""
    if tracker is None:
        return list(range(len(people)))
    if not people:
        return tracker(np.zeros((0, 33, 3)), np.zeros((0, APPEARANCE_SIZE), np.float32))
    landmarks = np.stack([p.body[:, [0, 1, 3]] for p in people])
    return tracker(landmarks, np.stack([appearance(image, p.body) for p in people]), [p.track for p in people])


def landmark_distance(track: Track, landmarks: np.ndarray, frame: int) -> float:
    """Mean distance, in the track's sizes, of the landmarks seen in both from where the track expects them."""
    both = _seen_in_both(track.landmarks, landmarks)
    expected = track.landmarks[both, :2] + track.velocity * (frame - track.last_seen)
    return float(np.linalg.norm(expected - landmarks[both, :2], axis=1).mean() / max(track.size, 1.0))


def appearance_distance(a: np.ndarray, b: np.ndarray) -> float:
    """Hellinger distance of two histograms in [0, 1]; 0.5 (undecided) when either is unknown."""
    if not a.any() or not b.any():
        return 0.5
    return float(np.sqrt(max(0.0, 1.0 - np.sum(np.sqrt(a * b)))))


class IdentityTracker:
    """``ids = tracker(landmarks, appearances, sources)`` once per frame, for that frame's people: ``landmarks``
    (P, K, 3) pixels and visibility, ``appearances`` (P, D) (`appearance`), ``sources`` (P,) the detector's tracks
    (`Person.track`; -1 or None: unknown). A person the detector tracked from the previous frame keeps that frame's
    identity: its landmark model follows them however their landmarks jump (a person cut by the frame's edge, whom
    it lays down in one frame and stands up in the next). Any other person matches the track whose expected
    landmarks lie within ``gate`` sizes (widening with the frames it was unseen) and whose look is within
    ``max_appearance``; of those pairs, the ones that match the most people, and among them the least total cost
    (distance + look; `assignment.gated_pairs`). ``state``/``restore`` carry the tracks over (e.g. between the
    chunks of a resumable run)."""

    def __init__(self, max_gap: int = 60, gate: float = 0.35, gate_per_frame: float = 0.05,
                 max_appearance: float = 0.6):
        self.max_gap, self.gate, self.gate_per_frame = max_gap, gate, gate_per_frame
        self.max_appearance = max_appearance
        self.tracks: list[Track] = []
        self.frame = 0
        self.next_id = 0

    def __call__(self, landmarks: np.ndarray, appearances: np.ndarray, sources=None) -> list[int]:
        frame = self.frame
        live = [t for t in self.tracks if frame - t.last_seen <= self.max_gap]
        sources = [-1] * len(landmarks) if sources is None else list(sources)
        followed = {t.source: k for k, t in enumerate(live) if t.source >= 0 and t.last_seen == frame - 1}
        pairs = {p: followed[s] for p, s in enumerate(sources) if s in followed}
        rows = [p for p in range(len(landmarks)) if p not in pairs]
        columns = [k for k in range(len(live)) if k not in pairs.values()]
        cost = np.full((len(rows), len(columns)), np.inf)
        for i, p in enumerate(rows):
            for j, k in enumerate(columns):
                gap = frame - live[k].last_seen
                moved = landmark_distance(live[k], landmarks[p], frame)
                differs = appearance_distance(live[k].appearance, appearances[p])
                if moved <= self.gate + self.gate_per_frame * (gap - 1) and differs <= self.max_appearance:
                    cost[i, j] = moved + differs
        pairs |= {rows[i]: columns[j] for i, j in gated_pairs(cost)}
        ids = [None] * len(landmarks)
        for p, k in pairs.items():
            ids[p], live[k] = live[k].id, _updated(live[k], landmarks[p], appearances[p], frame, sources[p])
        for p in range(len(landmarks)):
            if ids[p] is None:
                ids[p] = self.next_id
                live.append(_new_track(self.next_id, landmarks[p], appearances[p], frame, sources[p]))
                self.next_id += 1
        self.tracks, self.frame = live, frame + 1
        return ids

    def state(self) -> dict[str, np.ndarray]:
        """The tracker as arrays (``np.savez``-able)."""
        fields = [f.name for f in dataclasses.fields(Track)]
        tracks = {f"track_{f}": np.asarray([getattr(t, f) for t in self.tracks]) for f in fields}
        return tracks | {"frame": np.asarray(self.frame), "next_id": np.asarray(self.next_id)}

    def restore(self, state: dict[str, np.ndarray]) -> None:
        fields = [f.name for f in dataclasses.fields(Track)]
        count = len(state["track_id"])
        self.tracks = [Track(**{f: _scalar(state[f"track_{f}"][i]) for f in fields}) for i in range(count)]
        self.frame, self.next_id = int(state["frame"]), int(state["next_id"])


def _seen_in_both(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The landmarks visible in both ``a`` and ``b`` (K, 3); all of them when fewer than four are."""
    both = (a[:, 2] >= MIN_VISIBILITY) & (b[:, 2] >= MIN_VISIBILITY)
    return both if both.sum() >= 4 else np.ones(len(b), bool)


def _scalar(value):
    return value.item() if np.ndim(value) == 0 else value


def _size(landmarks: np.ndarray) -> float:
    """The larger side of the box of the visible landmarks: a person's height, or their length when the landmark
    model lays them down (someone cut by the frame's edge)."""
    seen = landmarks[landmarks[:, 2] >= MIN_VISIBILITY, :2]
    seen = seen if len(seen) >= 2 else landmarks[:, :2]
    return float(np.max(seen.max(0) - seen.min(0)))


def _new_track(track_id: int, landmarks: np.ndarray, look: np.ndarray, frame: int, source: int) -> Track:
    return Track(track_id, np.asarray(landmarks, np.float64), np.zeros(2), max(_size(landmarks), 1.0),
                 np.asarray(look, np.float32), frame, 1, int(source))


def _updated(track: Track, landmarks: np.ndarray, look: np.ndarray, frame: int, source: int) -> Track:
    """The track after seeing its person at ``frame``: velocity and size smoothed, appearance a running mean."""
    seen = _seen_in_both(track.landmarks, landmarks)
    step = (landmarks[seen, :2].mean(0) - track.landmarks[seen, :2].mean(0)) / (frame - track.last_seen)
    velocity = step if track.seen == 1 else 0.5 * track.velocity + 0.5 * step
    size = 0.8 * track.size + 0.2 * max(_size(landmarks), 1.0)
    look = np.asarray(look, np.float32)
    weight = 1.0 / min(track.seen + 1, 30)
    mixed = look if not track.appearance.any() else track.appearance if not look.any() else (
        (1 - weight) * track.appearance + weight * look)
    return Track(track.id, np.asarray(landmarks, np.float64), velocity, size, mixed, frame, track.seen + 1,
                 int(source))
