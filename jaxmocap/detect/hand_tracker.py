"""Hands on their own, no body needed, as mediapipe's hand solution finds them: palms over the whole image, up to
``max_hands``, each tracked from its own landmarks in a video, with its side from the handedness model.

    hands = HandTracker(static_image_mode=True)(cv2.imread("hand.jpg"))   # [Hand(side="left", ...)]
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from smplx_jax import SIDES

from .detector import as_bgr
from .hands import MIN_PALM_SCORE, MIN_PRESENCE, HandEstimator, HandResult
from .models import ensure_models
from .pose import rect_iou
from .track_state import result_of, results_state

# two hands whose corresponding landmarks lie this close on average, in the larger one's palm lengths (wrist to middle
# knuckle), are one hand seen twice (a palm detection on its fingers gives a second, smaller hand laid over them;
# both are tracked, as mediapipe tracks them, and the hand is reported once): a hand's landmarks stray by some
# hundredths of a palm from frame to frame, and two hands, however they touch or clasp, hold their wrists and
# fingers apart; only palms pressed together face-on look the same
SAME_HAND = 0.5


@dataclass(frozen=True)
class Hand:
    """One hand in one image. ``hand_id``: its track (kept while tracked in a video; in a still, the order found);
    ``side``: ``"left"`` or ``"right"`` (the person's); ``keypoints (21, 3)``: pixels x, y and z in x's scale,
    OpenPose hand order; ``world (21, 3)``: metres; ``score``: presence; ``right_score``: the handedness model's
    probability of a right hand in this image; ``box``: pixels x0, y0, x1, y1."""

    hand_id: int
    side: str
    keypoints: np.ndarray
    world: np.ndarray
    score: float
    right_score: float
    box: np.ndarray

    @property
    def keypoints_2d(self) -> np.ndarray:
        """(21, 3) pixels x, y and the hand's presence as each point's confidence (OpenPose's layout)."""
        return np.concatenate([self.keypoints[:, :2], np.full((21, 1), self.score)], axis=1)


@dataclass
class _Track:
    hand_id: int
    result: HandResult
    right_total: float  # sum of the handedness model's right scores over the frames tracked
    frames: int
    last_seen: int = 0  # the frame it was last seen in

    @property
    def right_mean(self) -> float:
        return self.right_total / self.frames


class HandTracker:
    """Palm detector and hand landmark model over whole images.

    ``static_image_mode=True``: every call is an unrelated image (palm detection, then the landmarks, refined once
    from their own box). ``False``: a video; each hand's next box comes from its landmarks, and the palm detector
    runs on every frame where fewer than ``max_hands`` are tracked (as mediapipe's hand solution gates it): a hand
    lost to blur or speed is sought again in the next frame, not after an interval.
    A hand found again within ``remember`` frames of losing it, near where it was (its centre within its size),
    takes up its identity and handedness. A hand's side is its handedness averaged over the frames it is tracked;
    of two hands taken for the same side, the one less likely so gets the other (two hands in view are mostly one
    person's pair). Two tracks on one hand (`SAME_HAND`) are reported as one, the one tracked longest.
    """

    def __init__(self, static_image_mode: bool = True, max_hands: int = 2, model_dir=None, num_threads: int = 2,
                 min_detection_confidence: float = MIN_PALM_SCORE, min_tracking_confidence: float = MIN_PRESENCE,
                 remember: int = 30):
        if max_hands < 1:
            raise ValueError(f"max_hands must be >= 1, got {max_hands}")
        paths = ensure_models(model_dir)
        self.static_image_mode = static_image_mode
        self.max_hands = max_hands
        self.min_detection_confidence = min_detection_confidence
        self.min_tracking_confidence = min_tracking_confidence
        self.remember = remember
        self._hands = HandEstimator(paths["palm_detection_full.tflite"], paths["hand_landmark_full.tflite"],
                                    num_threads=num_threads)
        self._tracks: list[_Track] = []
        self._lost: list[_Track] = []  # lost within `remember` frames
        self._frame = 0
        self._next_id = 0

    def reset(self) -> None:
        """Forget the tracked hands (start of a new video)."""
        self._tracks, self._lost, self._frame, self._next_id = [], [], 0, 0

    def state(self) -> dict[str, np.ndarray]:
        """The tracked (and lately lost) hands as arrays; `restore` continues from them as this tracker would."""
        tracks = self._tracks + self._lost
        out = {"frame": np.asarray(self._frame), "next_id": np.asarray(self._next_id),
               "tracked": np.asarray(len(self._tracks))}
        for name in ("hand_id", "right_total", "frames", "last_seen"):
            out[name] = np.asarray([getattr(t, name) for t in tracks], np.float64)
        return out | results_state("result", HandResult, [t.result for t in tracks])

    def restore(self, state: dict[str, np.ndarray]) -> None:
        """Continue from a `state`."""
        tracks = [_Track(int(state["hand_id"][k]), result_of(state, "result", HandResult, k),
                         float(state["right_total"][k]), int(state["frames"][k]), int(state["last_seen"][k]))
                  for k in range(len(state["hand_id"]))]
        tracked = int(state["tracked"])
        self._tracks, self._lost = tracks[:tracked], tracks[tracked:]
        self._frame, self._next_id = int(state["frame"]), int(state["next_id"])

    def _found(self, image: np.ndarray, known: list[HandResult], refine: bool) -> list[HandResult]:
        """New hands from the palm detector, best first, none where a known hand is."""
        size = (image.shape[1], image.shape[0])
        found = list(known)
        for det in self._hands.detect(image, self.min_detection_confidence):
            if len(found) >= self.max_hands:
                break
            roi = self._hands.detection_roi(det, size)
            if any(rect_iou(roi, h.roi) > 0.5 or rect_iou(roi, h.next_roi) > 0.5 for h in found):
                continue
            hand = self._hands.landmarks(image, roi, self.min_tracking_confidence)
            if hand is not None and refine:
                hand = self._hands.landmarks(image, hand.next_roi, self.min_tracking_confidence) or hand
            if hand is not None and not any(rect_iou(hand.next_roi, h.next_roi) > 0.5 for h in found):
                found.append(hand)
        return found[len(known):]

    def _tracked(self, image: np.ndarray) -> list[_Track]:
        if self.static_image_mode:
            return [_Track(k, h, h.right_score, 1) for k, h in enumerate(self._found(image, [], refine=True))]
        size = (image.shape[1], image.shape[0])
        tracks, lost = [], [t for t in self._lost if self._frame - t.last_seen <= self.remember]
        for track in self._tracks:
            hand = self._hands.landmarks(image, track.result.next_roi, self.min_tracking_confidence)
            if hand is None or any(rect_iou(hand.next_roi, t.result.next_roi) > 0.5 for t in tracks):
                lost.append(track)
                continue
            tracks.append(_Track(track.hand_id, hand, track.right_total + hand.right_score, track.frames + 1,
                                 self._frame))
        if len(tracks) < self.max_hands:
            for hand in self._found(image, [t.result for t in tracks], refine=False):
                before = _nearest(lost, hand, size)
                if before is None:
                    tracks.append(_Track(self._next_id, hand, hand.right_score, 1, self._frame))
                    self._next_id += 1
                else:
                    lost.remove(before)
                    tracks.append(_Track(before.hand_id, hand, before.right_total + hand.right_score,
                                         before.frames + 1, self._frame))
        self._lost = lost
        return tracks

    def __call__(self, image_bgr: np.ndarray) -> list[Hand]:
        """The hands in one BGR (or grayscale / BGRA) image, by ``hand_id``; in a video, its next frame."""
        image = as_bgr(image_bgr)
        tracks = self._tracked(image)
        if not self.static_image_mode:
            self._tracks = tracks
            self._frame += 1
        size = (image.shape[1], image.shape[0])
        shown = []  # each hand once: of tracks on one hand (`SAME_HAND`), the one tracked longest
        for track in sorted(tracks, key=lambda t: (-t.frames, t.hand_id)):
            if not any(hand_gap(track.result, other.result, size) < SAME_HAND for other in shown):
                shown.append(track)
        tracks = sorted(shown, key=lambda t: t.hand_id)
        sides = [SIDES[t.right_mean > 0.5] for t in tracks]
        if len(tracks) == 2 and sides[0] == sides[1]:
            more_right = int(tracks[1].right_mean > tracks[0].right_mean)
            sides = ["left", "left"]
            sides[more_right] = "right"
        w, h = image.shape[1], image.shape[0]
        hands = []
        for track, side in zip(tracks, sides):
            pixels = track.result.landmarks * (w, h, w)
            box = np.concatenate([pixels[:, :2].min(0), pixels[:, :2].max(0)])
            hands.append(Hand(track.hand_id, side, pixels, track.result.world, track.result.presence,
                              track.result.right_score, box))
        return sorted(hands, key=lambda hand: hand.hand_id)


def hand_gap(a: HandResult, b: HandResult, image_size: tuple[int, int]) -> float:
    """The mean distance of two hands' corresponding landmarks, in the larger one's palm lengths."""
    pa, pb = a.landmarks[:, :2] * image_size, b.landmarks[:, :2] * image_size
    palm = max(np.linalg.norm(pa[9] - pa[0]), np.linalg.norm(pb[9] - pb[0]), 1e-9)
    return float(np.linalg.norm(pa - pb, axis=1).mean() / palm)


def _nearest(lost: list[_Track], hand: HandResult, image_size: tuple[int, int]) -> _Track | None:
    """The lost track nearest ``hand`` whose centre was within its size of the hand's, or None."""
    w, h = image_size

    def distance(track):
        a, b = track.result.next_roi, hand.next_roi
        return np.hypot((a.x_center - b.x_center) * w, (a.y_center - b.y_center) * h) / max(a.width * w, 1e-9)

    near = [t for t in lost if distance(t) < 1.0]
    return min(near, key=distance, default=None)
