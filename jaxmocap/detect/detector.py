"""Whole-body detection of people in one image or a video stream: pose, then hands attached to each body."""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import cv2
import numpy as np

from smplx_jax import SIDES

from .assignment import gated_pairs
from .hands import MIN_PRESENCE as MIN_HAND_PRESENCE
from .hands import POSE_HAND_POINTS, HandEstimator, HandResult, keeps_tracking, pose_hand_roi
from .models import ensure_models, landmark_model_path
from .pose import PoseEstimator, PoseResult, Silhouette, landmark_box, overlap, rect_extent, rect_iou
from .roi import Rect, normalize_radians
from .ssd import Detection, in_image, square_tiles
from .track_state import result_of, results_state

SEARCH_SECONDS = 0.2  # while fewer than max_people are tracked, the person detector looks for more this often
BONES = np.array([(11, 13), (13, 15), (12, 14), (14, 16), (11, 12), (23, 24), (11, 23), (12, 24), (23, 25),
                  (25, 27), (24, 26), (26, 28), (0, 11), (0, 12)])  # BlazePose landmarks: arms, torso, legs, head
CONFIRM_FRAMES = 2  # a person found beside others is reported once tracked in this many frames
# a person detection on which the landmark model's presence is below min_tracking_confidence but at least this
# (someone cut by the frame's edge, whose presence swings across that range from frame to frame)
# starts a burst of searches, as a lost track does (`Detector`)
DOUBTFUL_PRESENCE = 0.1
UPSIDE_DOWN = 0.75 * math.pi  # a detection turned more than this (radians) is tried upright too
# BlazePose's landmarks with left and right exchanged: nose, eyes, ears, mouth, then the pairs from the shoulders down
SIDES_EXCHANGED = np.array([0, 4, 5, 6, 1, 2, 3, 8, 7, 10, 9, *np.arange(11, 33).reshape(-1, 2)[:, ::-1].ravel()])
# two skeletons are one person's when their landmarks lie this close on average (torso lengths): a limb's radius
# (about a sixth of the torso) and the landmark model's noise between two crops of one person; two people whose
# skeletons came this close would stand inside each other
SAME_SKELETON = 0.25
# someone found beside people hidden from view (`Detector._detect_people`) is taken when the landmark model sees at
# least this many of their 33 landmarks (visibility at least 0.5): a third of a body, as of anyone half hidden;
# a skeleton laid over a thing in the background is mostly guessed
MIN_SEEN_BEHIND = 11
# a track's person is not further from their last skeleton than this (torso lengths, on average over the landmarks:
# about 25 cm, what a body moves in a frame at 15 frames/s and 4 m/s; people move a tenth of it in a frame at 30
# frames/s); a track lost in a frame is continued by someone the person detector finds this close in that frame
REFOUND_GAP = 0.5
# a hand belongs to a body's wrist within this many of its palm lengths (wrist to middle knuckle: a hand's reach)
MAX_WRIST_PALMS = 2.0


def search_interval(fps: float | None) -> int:
    """Frames between searches for more people in a video of ``fps`` frames/s (6 when unknown)."""
    return max(1, int(SEARCH_SECONDS * fps)) if fps else 6


_NO_HAND = HandResult(np.zeros((21, 3)), np.zeros((21, 3)), 0.0, 0.0, Rect(0, 0, 0, 0), Rect(0, 0, 0, 0))


@dataclass(frozen=True)
class Person:
    """One person in one image; pixel coordinates (x right, y down), z in the same pixel scale as x.

    ``body`` (33, 4) BlazePose landmarks x, y, z, visibility; ``body_world`` (33, 3) metres about the hips;
    ``left_hand`` / ``right_hand`` (21, 3) x, y, z in OpenPose hand order, or None when not found, with
    ``*_hand_world`` (21, 3) metres and ``*_hand_score`` the hand presence (0 when missing); ``box`` the body's
    pixel box (x0, y0, x1, y1) from its landmarks; ``*_hand_box`` the hand's, or None; ``score`` the pose presence;
    ``track`` the detector's track of the person (in tracking mode the same number for as long as it follows them
    from frame to frame, new numbers for people found anew; -1 for still images).
    """

    body: np.ndarray
    body_world: np.ndarray
    left_hand: np.ndarray | None
    right_hand: np.ndarray | None
    left_hand_world: np.ndarray | None
    right_hand_world: np.ndarray | None
    left_hand_score: float
    right_hand_score: float
    box: np.ndarray
    left_hand_box: np.ndarray | None
    right_hand_box: np.ndarray | None
    score: float
    track: int = -1


def as_bgr(image: np.ndarray) -> np.ndarray:
    """A contiguous uint8 BGR image from a grayscale, BGR or BGRA array (8- or 16-bit)."""
    image = np.asarray(image)
    if image.dtype == np.uint16:
        image = (image >> 8).astype(np.uint8)
    elif image.dtype != np.uint8:
        raise ValueError(f"image must be uint8 (or uint16), got {image.dtype}")
    if image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 1):
        image = cv2.cvtColor(image.reshape(image.shape[:2]), cv2.COLOR_GRAY2BGR)
    elif image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    elif not (image.ndim == 3 and image.shape[2] == 3):
        raise ValueError(f"image must be (H, W), (H, W, 1), (H, W, 3) or (H, W, 4), got shape {image.shape}")
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise ValueError(f"image is too small: {image.shape[1]}x{image.shape[0]}")
    return np.ascontiguousarray(image)


@dataclass
class _Track:
    pose: PoseResult
    hands: dict  # side -> HandResult | None
    seen: int = CONFIRM_FRAMES  # frames tracked (`CONFIRM_FRAMES` for one reported at once)
    number: int = -1  # the detector's count of tracks started before this one (`Person.track`)
    behind: bool = False  # followed with the others hidden (`Detector._tracked`)


class Detector:
    """BlazePose + hand landmarks for up to ``max_people`` people.

    ``static_image_mode=True`` treats every call as an unrelated image (person and palm detectors each time);
    ``False`` tracks: the next ROIs come from the previous frame's landmarks, the person detector runs only when
    no one is tracked (or every ``redetect_every`` frames while fewer than ``max_people`` are tracked; for a video,
    `search_interval` of its frame rate, so that someone who comes in is found within a quarter second; and in each
    frame for as long after a track is lost, or a detection the landmark model is unsure of), and each
    hand comes, as in mediapipe's holistic, from the ROI that the body's wrist, pinky and index give, refined by
    the recrop model, or from the previous frame's hand while that stays close to it. ``hands=False``: bodies
    alone, the hand models not even loaded. ``landmarks``: BlazePose's landmark model, ``full`` (the wheel's),
    ``heavy`` or ``lite`` (`jaxmocap.detect.models.LANDMARK_MODELS`; same inputs and outputs).
    Model files: see ``jaxmocap.detect.models`` (``model_dir`` or ``$JAXMOCAP_MEDIAPIPE_DIR`` to use a copy); a
    landmark model that cannot be had is an error here (`available_landmarks` chooses one that can).
    """

    def __init__(self, static_image_mode: bool = True, max_people: int = 1, hands: bool = True,
                 model_dir=None, num_threads: int = 2, min_detection_confidence: float = 0.5,
                 min_tracking_confidence: float = 0.5, redetect_every: int = 6, landmarks: str = "full"):
        if max_people < 1:
            raise ValueError(f"max_people must be >= 1, got {max_people}")
        landmark_path = landmark_model_path(landmarks, model_dir)
        paths = ensure_models(model_dir)
        self.landmarks = landmarks
        self.static_image_mode = static_image_mode
        self.max_people = max_people
        self.with_hands = hands
        self.min_detection_confidence = min_detection_confidence
        self.min_tracking_confidence = min_tracking_confidence
        self.redetect_every = redetect_every
        self._pose = PoseEstimator(paths["pose_detection.tflite"], landmark_path, num_threads)
        self._hands = HandEstimator(paths["palm_detection_full.tflite"], paths["hand_landmark_full.tflite"],
                                    paths["hand_recrop.tflite"], num_threads) if hands else None
        self._tracks: list[_Track] = []
        self._searches_left = 0  # frames left in a burst of searches (`_people`)
        self._frame = 0
        self._started = 0  # tracks started

    def reset(self) -> None:
        """Forget the tracked people (start of a new video)."""
        self._tracks = []
        self._searches_left = 0
        self._frame = 0
        self._started = 0

    def state(self) -> dict[str, np.ndarray]:
        """The tracked people as arrays (``np.savez``-able); `restore` continues from them exactly as this
        detector would (a resumed run detects as an uninterrupted one)."""
        hands = [[t.hands.get(side) for side in SIDES] for t in self._tracks]
        out = {"frame": np.asarray(self._frame), "started": np.asarray(self._started),
               "seen": np.asarray([t.seen for t in self._tracks], np.int64),
               "number": np.asarray([t.number for t in self._tracks], np.int64),
               "behind": np.asarray([t.behind for t in self._tracks], bool),
               "hand_found": np.asarray(
            [[h is not None for h in pair] for pair in hands], bool).reshape(-1, 2),
               "searches_left": np.asarray(self._searches_left)}
        return out | results_state("pose", PoseResult, [t.pose for t in self._tracks]) | results_state(
            "hand", HandResult, [h for pair in hands for h in pair], _NO_HAND)

    def restore(self, state: dict[str, np.ndarray]) -> None:
        """Continue from a `state`."""
        found = state["hand_found"]
        self._tracks = [_Track(result_of(state, "pose", PoseResult, k), {
            side: result_of(state, "hand", HandResult, 2 * k + j) if found[k, j] else None
            for j, side in enumerate(SIDES)},
            int(state["seen"][k]), int(state["number"][k]), bool(state["behind"][k])) for k in range(len(found))]
        self._searches_left = int(state["searches_left"])
        self._frame, self._started = int(state["frame"]), int(state["started"])

    # -- body -------------------------------------------------------------------------------------------------
    def _person_detections(self, image: np.ndarray) -> list[Detection]:
        """The person detector on the whole (letterboxed) image, best first, then on squares along its long side,
        where people are seen at twice the size or more, best first (duplicates of one person are left to the
        caller). The whole image's come first, as mediapipe takes them: the squares add people, never a crop other
        than mediapipe's for the first one (ordered by score together, a square's higher score moved it)."""
        size = (image.shape[1], image.shape[0])
        tiles = []
        for x0, y0, side in square_tiles(size):
            tile = image[y0:y0 + side, x0:x0 + side]
            tiles += [in_image(d, (x0, y0, side), size)
                      for d in self._pose.detect(tile, self.min_detection_confidence)]
        whole = self._pose.detect(image, self.min_detection_confidence)
        return sorted(whole, key=lambda d: -d.score) + sorted(tiles, key=lambda d: -d.score)

    def _detect_people(self, image: np.ndarray, known: list[PoseResult]) -> tuple[list[PoseResult], bool]:
        """The people the person detector finds beside the ``known`` ones, and whether it found someone the
        landmark model was unsure of (`DOUBTFUL_PRESENCE`). First in the image as it is, passing over detections
        whose ROI is mostly one found already (IoU above 0.5: them again); then, after each pass that found
        someone, in the image with the people known or found so far greyed out (`_hidden`), taking detections whose
        ROI overlaps one of them and who show a third of their landmarks (`MIN_SEEN_BEHIND`): someone half hidden
        by another person, whose detection the suppression of overlapping boxes merges into theirs, and on whose
        crop the landmark model goes to the one it sees whole."""
        size = (image.shape[1], image.shape[0])
        found, unsure = list(known), False
        silhouettes: list[Silhouette | None] = [None] * len(known)  # the known ones' when first needed
        candidates, first = [(image, d) for d in self._person_detections(image)], True
        while len(found) < self.max_people:
            before = len(found)
            for seen, det in candidates:
                if len(found) >= self.max_people:
                    break
                roi = self._pose.detection_roi(det, size)
                if first and any(rect_iou(roi, p.roi) > 0.5 or rect_iou(roi, p.next_roi) > 0.5 for p in found):
                    continue
                result, silhouette = self._upright(seen, roi)
                if result.presence < self.min_tracking_confidence:
                    unsure |= result.presence >= DOUBTFUL_PRESENCE
                elif not first and np.sum(result.landmarks[:, 3] >= 0.5) < MIN_SEEN_BEHIND:
                    continue
                elif not any(_same_person(result, p, size) for p in found):
                    found.append(result)
                    silhouettes.append(silhouette)
            if not found or len(found) == before and not first:
                break
            silhouettes = [self._pose.observe(image, p.roi, 0.0)[1] if s is None else s
                           for p, s in zip(found, silhouettes)]
            seen, boxes = self._hidden(image, silhouettes), [landmark_box(p.landmarks, size) for p in found]
            candidates, first = [(seen, d) for d in self._person_detections(seen)
                                 if _overlaps(self._pose.detection_roi(d, size), boxes, size)], False
        return found[len(known):], unsure

    def _hidden(self, image: np.ndarray, silhouettes: list[Silhouette]) -> np.ndarray:
        """The image with the ``silhouettes`` filled with mid grey: what is left for someone else."""
        if not silhouettes:
            return image
        size = (image.shape[1], image.shape[0])
        hidden = image.copy()
        for silhouette in silhouettes:
            hidden[silhouette.mask(size)] = 128
        return hidden

    def _upright(self, image: np.ndarray, roi: Rect) -> tuple[PoseResult, Silhouette]:
        """The landmarks in a person detection's ``roi`` and the person's silhouette; where that stands the person
        on their head (turned by more than `UPSIDE_DOWN`), also in it turned by 180 degrees, and the more present of
        the two. Cut by the frame's edge, a person's detection can point the wrong way, and on the upturned crop the
        landmark model lays a whole skeleton head down over them, which tracking then follows."""
        seen = self._pose.observe(image, roi, 0.0)
        if abs(normalize_radians(roi.rotation)) <= UPSIDE_DOWN:
            return seen
        turned = self._pose.observe(image, roi._replace(rotation=normalize_radians(roi.rotation + math.pi)), 0.0)
        return turned if turned[0].presence > seen[0].presence else seen

    def _tracked(self, image: np.ndarray) -> list[tuple[PoseResult | None, bool]]:
        """Each track's pose this frame from its tracking ROI (None where lost) and whether it is behind someone.
        A pose that does not stay with its track's person (`_stays`) went to someone else: the track is sought
        again with that one's silhouette greyed out, and is lost if it is not found near where it was. In a crop
        holding two people the landmark model goes to the one it sees whole, so a track behind someone (found with
        others hidden, `_detect_people`; sought again, here or in `_apart`) is followed on the image with the
        other tracks' silhouettes greyed out, for as long as its landmarks' box overlaps theirs."""
        size = (image.shape[1], image.shape[0])
        tracks = self._tracks
        seen = [(None, None) if t.behind else self._pose.observe(image, t.pose.next_roi, self.min_tracking_confidence)
                for t in tracks]
        poses, silhouettes = [list(column) for column in zip(*seen)] if seen else ([], [])
        strayed = {k for k, pose in enumerate(poses) if pose is not None and not self._stays(pose, k, size)}
        again = sorted(strayed | {k for k, t in enumerate(tracks) if t.behind})
        for k in again:
            others = [silhouettes[k]] if k in strayed else []  # whom its pose went to
            others += [silhouettes[j] if silhouettes[j] is not None and j not in strayed else
                       self._pose.observe(image, tracks[j].pose.next_roi, 0.0)[1] for j in range(len(tracks)) if j != k]
            pose, silhouette = self._pose.observe(self._hidden(image, others), tracks[k].pose.next_roi,
                                                  self.min_tracking_confidence)
            poses[k], silhouettes[k] = (pose, silhouette) if pose is not None and self._stays(pose, k, size) else (
                None, None)
        poses, moved = self._apart(image, poses, silhouettes)
        boxes = [None if p is None else landmark_box(p.landmarks, size) for p in poses]
        return [(pose, (k in again or k in moved) and any(
            overlap(boxes[k], box) > 0 for j, box in enumerate(boxes) if j != k and box is not None))
            if pose is not None else (None, False) for k, pose in enumerate(poses)]

    def _stays(self, pose: PoseResult, k: int, size: tuple[int, int]) -> bool:
        """Whether a pose found by track ``k`` is its person's: within `REFOUND_GAP` of the track's last skeleton
        (no body moves further in a frame), and not on another track's last skeleton rather than on its own."""
        last = self._tracks[k].pose
        return skeleton_gap(pose, last, size) < REFOUND_GAP and (_coincide(pose, last, size) or not any(
            _coincide(pose, t.pose, size) for j, t in enumerate(self._tracks) if j != k))

    def _apart(self, image: np.ndarray, poses: list[PoseResult | None], silhouettes: list[Silhouette | None]
               ) -> tuple[list[PoseResult | None], set[int]]:
        """The tracks' poses (in the order of ``self._tracks``; None where lost), each on its own person, and the
        tracks sought again. Where two coincide (`_coincide`), one landmark model left its person for the other,
        whom the other track follows: the pose stays with the track whose last skeleton it is nearer
        (`skeleton_gap`), and the other track is sought again in its ROI with that person's silhouette greyed out
        (`_hidden`); lost if it still finds no one else."""
        size = (image.shape[1], image.shape[0])
        poses, moved = list(poses), set()
        for i, j in itertools.combinations(range(len(poses)), 2):
            a, b = poses[i], poses[j]
            if a is None or b is None or not _coincide(a, b, size) and not _coincide(b, a, size):
                continue
            stays = skeleton_gap(a, self._tracks[i].pose, size) <= skeleton_gap(b, self._tracks[j].pose, size)
            keeper, left = (i, j) if stays else (j, i)
            found = self._pose.landmarks(self._hidden(image, [silhouettes[keeper]]), self._tracks[left].pose.next_roi,
                                         self.min_tracking_confidence)
            apart = found is not None and not _coincide(found, poses[keeper], size) and not _coincide(
                poses[keeper], found, size)
            poses[left] = found if apart else None
            moved.add(left)
        return poses, moved

    def _people(self, image: np.ndarray) -> list[_Track]:
        if self.static_image_mode:
            return [_Track(p, {s: None for s in SIDES}) for p in self._detect_people(image, [])[0]]
        followed = self._tracked(image)
        tracks = [_Track(pose, track.hands, track.seen + 1, track.number, behind)
                  for track, (pose, behind) in zip(self._tracks, followed) if pose is not None]
        missing = [track for track, (pose, _) in zip(self._tracks, followed) if pose is None]
        new, lost = [], bool(missing)
        if not tracks or (len(tracks) < self.max_people
                          and (self._frame % self.redetect_every == 0 or lost or self._searches_left)):
            new, unsure = self._detect_people(image, [t.pose for t in tracks])
            # someone lost, or someone the landmark model was unsure of: searched for in each frame for the
            # next search interval (a burst, not restarted while it lasts)
            self._searches_left = (self.redetect_every - 1 if (lost or unsure) and not self._searches_left
                                   else max(self._searches_left - 1, 0))
        # someone found where a track was lost this frame is its person, found again; the first person of a stream
        # is reported at once; anyone else found beside others once tracked in `CONFIRM_FRAMES` frames (a detection
        # that does not survive them is a false one, often a part of someone), and followed with the others hidden
        # for as long as they overlap them (`_tracked`)
        size = (image.shape[1], image.shape[0])
        gaps = np.array([[skeleton_gap(p, t.pose, size) for t in missing] for p in new]).reshape(len(new), len(missing))
        again = dict(gated_pairs(np.where(gaps < REFOUND_GAP, gaps, np.inf)))
        first = not tracks
        for k, p in enumerate(new):
            if k in again:
                track = missing[again[k]]
                tracks.append(_Track(p, track.hands, track.seen + 1, track.number, bool(tracks)))
            else:
                tracks.append(_Track(p, {s: None for s in SIDES}, CONFIRM_FRAMES if first and not k else 1,
                                     self._started, bool(tracks)))
                self._started += 1
        return tracks

    # -- hands ------------------------------------------------------------------------------------------------
    def _hand_from_pose(self, image: np.ndarray, pose: PoseResult, side: str, previous: HandResult | None
                        ) -> HandResult | None:
        """Holistic's hand: the recrop ROI from the pose, or the previous hand's ROI while it stays close."""
        if pose.landmarks[POSE_HAND_POINTS[side][0], 3] <= 0.1:  # holistic's wrist-visibility gate
            return None
        size = (image.shape[1], image.shape[0])
        recrop = self._hands.recrop_roi(image, pose_hand_roi(pose.landmarks, side, size))
        keep = previous is not None and keeps_tracking(previous, recrop, size)
        hand = self._hands.landmarks(image, previous.next_roi if keep else recrop, MIN_HAND_PRESENCE)
        if hand is None and previous is not None and not keep:  # the recrop missed: try where the hand was
            hand = self._hands.landmarks(image, previous.next_roi, MIN_HAND_PRESENCE)
            hand = hand if hand is not None and self._plausible(hand, pose, side, size) else None
        return hand

    def _seed_hand(self, image: np.ndarray, pose: PoseResult, side: str) -> HandResult | None:
        """A hand from the pose in a still image: holistic's, refined once from its own landmarks."""
        hand = self._hand_from_pose(image, pose, side, None)
        if hand is not None:
            hand = self._hands.landmarks(image, hand.next_roi, MIN_HAND_PRESENCE) or hand
        size = (image.shape[1], image.shape[0])
        return hand if hand is not None and self._plausible(hand, pose, side, size) else None

    @staticmethod
    def _wrist_cost(hand: HandResult, pose: PoseResult, side: str, size) -> float:
        """Distance hand wrist -> body wrist in palm lengths, plus a handedness penalty (tie-breaker)."""
        w, h = size
        wrist = pose.landmarks[POSE_HAND_POINTS[side][0], :2] * (w, h)
        hand_wrist = hand.landmarks[0, :2] * (w, h)
        palm = max(np.linalg.norm((hand.landmarks[9, :2] - hand.landmarks[0, :2]) * (w, h)), 1.0)
        p_side = hand.right_score if side == "right" else 1.0 - hand.right_score
        return float(np.linalg.norm(hand_wrist - wrist) / palm + 0.25 * (1.0 - p_side))

    def _plausible(self, hand: HandResult, pose: PoseResult, side: str, size) -> bool:
        return self._wrist_cost(hand, pose, side, size) < MAX_WRIST_PALMS

    def _assign_palms(self, image: np.ndarray, tracks: list[_Track]) -> None:
        size = (image.shape[1], image.shape[0])
        palms = self._hands.detect(image)[: 2 * len(tracks)]
        hands = [self._hands.landmarks(image, self._hands.detection_roi(d, size), self.min_tracking_confidence)
                 for d in palms]
        hands = [h for h in hands if h is not None]
        free = [(t, side) for t in tracks for side in SIDES if t.hands[side] is None]
        cost = np.array([[self._wrist_cost(h, t.pose, side, size) for t, side in free] for h in hands]).reshape(
            len(hands), len(free))
        for i, j in gated_pairs(np.where(cost < MAX_WRIST_PALMS, cost, np.inf)):
            track, side = free[j]
            track.hands[side] = hands[i]

    def _update_hands(self, image: np.ndarray, tracks: list[_Track]) -> None:
        if self.static_image_mode:
            self._assign_palms(image, tracks)
            for t in tracks:
                for side in SIDES:
                    if t.hands[side] is None:
                        t.hands[side] = self._seed_hand(image, t.pose, side)
            return
        for t in tracks:
            for side in SIDES:
                t.hands[side] = self._hand_from_pose(image, t.pose, side, t.hands[side])

    # -- public -----------------------------------------------------------------------------------------------
    def __call__(self, image_bgr: np.ndarray) -> list[Person]:
        """People in one BGR (or grayscale / BGRA) image; in tracking mode, the next frame of the stream."""
        image = as_bgr(image_bgr)
        tracks = self._people(image)
        if self.with_hands and tracks:
            if self.static_image_mode:
                for t in tracks:
                    t.hands = {s: None for s in SIDES}
            self._update_hands(image, tracks)
        else:
            for t in tracks:
                t.hands = {s: None for s in SIDES}
        if not self.static_image_mode:
            self._tracks = tracks
            self._frame += 1
        size = (image.shape[1], image.shape[0])
        return [_person(t, size) for t in tracks if t.seen >= CONFIRM_FRAMES]


def _coincide(new: PoseResult, known: PoseResult, size: tuple[int, int]) -> bool:
    """Whether ``new`` is ``known``'s pose again: their skeletons coincide (`skeleton_gap`), or ``new`` lies on
    ``known``'s body (`_on_body`)."""
    return skeleton_gap(new, known, size) < SAME_SKELETON or _on_body(new, known, size)


def _torso(points: np.ndarray) -> float:
    """The length (pixels) from mid-hip to mid-shoulder of BlazePose landmarks (33, 2) in pixels."""
    return float(np.linalg.norm(points[[11, 12]].mean(0) - points[[23, 24]].mean(0)))


def skeleton_gap(new: PoseResult, known: PoseResult, size: tuple[int, int]) -> float:
    """The mean distance of ``new``'s landmarks from ``known``'s, over those visible in both (all of them when
    fewer than four are), in ``known``'s torso lengths; the smaller of its two readings of left and right (the
    landmark model exchanges them on a person seen from behind)."""
    scale = np.asarray(size, np.float64)
    a, b = new.landmarks[:, :2] * scale, known.landmarks[:, :2] * scale
    torso = max(_torso(b), 1.0)
    gaps = []
    for order in (np.arange(33), SIDES_EXCHANGED):
        both = (new.landmarks[order, 3] >= 0.5) & (known.landmarks[:, 3] >= 0.5)
        both = both if both.sum() >= 4 else np.ones(33, bool)
        gaps.append(np.linalg.norm(a[order][both] - b[both], axis=1).mean() / torso)
    return float(min(gaps))


def _on_body(new: PoseResult, known: PoseResult, size: tuple[int, int]) -> bool:
    """Whether most (more than half) of ``new``'s visible landmarks lie on ``known``'s body: within a quarter of
    its torso's length of its skeleton (`BONES`), a limb's radius (a thigh's is about a sixth of the torso) and the
    landmark model's noise (a few hundredths of it). A second skeleton the landmark model laid over one person
    (their upper body taken for a whole person, or a deep bend) has every landmark on that body; of two people,
    however they overlap, one's visible landmarks are where the other does not hide them, so at most those along
    the edge they share lie on the other's body."""
    scale = np.asarray(size, np.float64)
    points = new.landmarks[:, :2] * scale
    visible = new.landmarks[:, 3] >= 0.5
    points = points[visible] if visible.sum() >= 4 else points
    skeleton = known.landmarks[:, :2] * scale
    torso = _torso(skeleton)
    start, bone = skeleton[BONES[:, 0]], skeleton[BONES[:, 1]] - skeleton[BONES[:, 0]]
    along = np.clip(np.einsum("pbk,bk->pb", points[:, None] - start, bone) / np.maximum(np.sum(bone**2, 1), 1e-9),
                    0.0, 1.0)
    distance = np.linalg.norm(points[:, None] - (start + along[..., None] * bone), axis=2).min(1)
    return bool(np.mean(distance < 0.25 * torso) > 0.5)


def _same_person(new: PoseResult, known: PoseResult, size: tuple[int, int]) -> bool:
    """Whether a person just found is one already known (`_coincide`), or a part of the known one taken for a
    small whole person (less than half as tall, and for the most part within the known one's rect)."""
    if _coincide(new, known, size):
        return True
    x0, y0, x1, y1 = box = landmark_box(new.landmarks, size)
    tall = landmark_box(known.landmarks, size)
    rect = np.asarray(rect_extent(known.next_roi)) * np.tile(size, 2)
    area = max((x1 - x0) * (y1 - y0), 1e-9)
    return bool(y1 - y0 < 0.5 * (tall[3] - tall[1]) and overlap(box, rect) > 0.8 * area)


def _overlaps(roi: Rect, boxes: list[np.ndarray], size: tuple[int, int]) -> bool:
    """Whether a ROI's extent, its rotation left out, overlaps one of the pixel ``boxes``."""
    extent = np.asarray(rect_extent(roi)) * np.tile(size, 2)
    return any(overlap(extent, box) > 0 for box in boxes)


def _person(track: _Track, size: tuple[int, int]) -> Person:
    w, h = size
    scale = np.array([w, h, w])
    body = np.concatenate([track.pose.landmarks[:, :3] * scale, track.pose.landmarks[:, 3:4]], axis=1)
    parts = {}
    for side in SIDES:
        hand = track.hands.get(side)
        if hand is None:
            parts[side] = (None, None, 0.0, None)
        else:
            px = hand.landmarks * scale
            box = np.array([px[:, 0].min(), px[:, 1].min(), px[:, 0].max(), px[:, 1].max()])
            parts[side] = (px, hand.world, hand.presence, box)
    return Person(
        body=body, body_world=track.pose.world,
        left_hand=parts["left"][0], right_hand=parts["right"][0],
        left_hand_world=parts["left"][1], right_hand_world=parts["right"][1],
        left_hand_score=parts["left"][2], right_hand_score=parts["right"][2],
        box=landmark_box(track.pose.landmarks, size), left_hand_box=parts["left"][3],
        right_hand_box=parts["right"][3], score=track.pose.presence, track=track.number)

