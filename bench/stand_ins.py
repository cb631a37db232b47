"""Stand-ins for footage of people who overlap (issue 70), made from the shipped clips, each with its truth: where
every person is in every frame and which of them can be seen.

- `near_crop`: Pose2Sim's two-person take cropped around the person nearest the camera and scaled up, so that
  they fill the frame and the other one passes behind them, cut by the frame's edges.
- `pasted`: a single-person take with a second person drawn in front of or behind its own: a copy of the same
  clip played backwards, its silhouette (BlazePose's segmentation) scaled and moved sideways by a quarter of the
  person's height, bigger and lower in the frame when in front (nearer the camera), smaller and higher behind.
- `turned`: any of them mirrored or turned by 90 degrees, the truth alike.

The truth of a person is BlazePose's landmarks of them in the take as shot (the detector tracking it; the pasted
copy's moved as its pixels were). A person counts as seen in a frame when at least half of their silhouette
(`MIN_SHARE`; BlazePose's segmentation) is in view: in the picture and not under the silhouette of the person
nearer the camera.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

MIN_SHARE = 0.5  # a person counts as seen when at least half of their silhouette is in view
# an identity tracks a person in a frame when its keypoints lie within a fifth of the person's height of where they
# are seen, on average: nearer than the other person wherever the two are told apart (the pairing takes the nearest)
MATCH_HEIGHTS = 0.2
# BODY_25 with left and right exchanged
BODY25_EXCHANGED = np.array([0, 1, 5, 6, 7, 2, 3, 4, 8, 12, 13, 14, 9, 10, 11, 16, 15, 18, 17, 22, 23, 24, 19, 20, 21])
OFFSET_HEIGHTS = 0.25  # the copy's sideways offset, in the person's heights: half a torso, so that they overlap
NEAR_SCALE, FAR_SCALE = 1.15, 0.85  # the copy's size in front of and behind the person
DROP_HEIGHTS = 0.08  # the copy's feet lower (in front) or higher (behind) by this many heights


@dataclass(frozen=True)
class Truth:
    """Each person's landmarks (P, T, 33, 3): pixels x, y and 1 where in view, 0 where not (outside the picture or
    under the nearer person's silhouette), NaN where unknown; ``seen`` (P, T) the frames in which each can be seen
    (`MIN_SHARE`)."""

    landmarks: np.ndarray
    seen: np.ndarray


def read(video: Path, count: int | None = None) -> tuple[list[np.ndarray], float]:
    """The frames of a video (BGR; the first ``count``, or all) and its frame rate."""
    cap = cv2.VideoCapture(str(video))
    fps, frames = cap.get(cv2.CAP_PROP_FPS), []
    while count is None or len(frames) < count:
        ok, frame = cap.read()
        if not ok:
            break
        frames.append(frame)
    cap.release()
    return frames, fps


def write(frames: list[np.ndarray], fps: float, out: Path) -> Path:
    writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"mp4v"), fps, frames[0].shape[1::-1])
    for frame in frames:
        writer.write(frame)
    writer.release()
    return out


def tracked(frames: list[np.ndarray], fps: float, max_people: int) -> np.ndarray:
    """The detector's people through the frames, by identity (``jaxmocap run``'s tracking): (P, T, 33, 3) pixels and
    visibility, NaN where not found."""
    from jaxmocap.detect import Detector
    from jaxmocap.detect.detector import search_interval
    from jaxmocap.detect.identities import IdentityTracker, identify

    detector = Detector(static_image_mode=False, max_people=max_people, hands=False,
                        redetect_every=search_interval(fps), landmarks="heavy")
    tracker, people = IdentityTracker(), {}
    for t, frame in enumerate(frames):
        found = detector(frame)
        for person, p in zip(identify(tracker, frame, found), found):
            people.setdefault(person, np.full((len(frames), 33, 3), np.nan))[t] = p.body[:, [0, 1, 3]]
    return np.stack([people[k] for k in sorted(people)]) if people else np.zeros((0, len(frames), 33, 3))


def silhouettes(frames: list[np.ndarray], landmarks: np.ndarray) -> np.ndarray:
    """The person's silhouette (T, H, W) in each frame, 0 or 1: BlazePose's segmentation (`PoseEstimator.observe`,
    the heavy landmark model) on an upright square around their landmarks (T, 33, >=2), zeros where unknown."""
    from jaxmocap.detect.models import ensure_models, landmark_model_path
    from jaxmocap.detect.pose import PoseEstimator
    from jaxmocap.detect.roi import Rect

    model = PoseEstimator(ensure_models()["pose_detection.tflite"], landmark_model_path("heavy"))
    height, width = frames[0].shape[:2]
    out = np.zeros((len(frames), height, width), np.float32)
    for t, (frame, points) in enumerate(zip(frames, landmarks)):
        if np.isfinite(points[:, :2]).all():
            low, high = points[:, :2].min(0), points[:, :2].max(0)
            centre, side = (low + high) / 2, 1.4 * float(np.max(high - low))
            roi = Rect(centre[0] / width, centre[1] / height, side / width, side / height)
            out[t] = model.observe(frame, roi, 0.0)[1].mask((width, height))
    return out


def _share(own: np.ndarray, cover: np.ndarray | None = None, whole: np.ndarray | None = None) -> np.ndarray:
    """(T,) the share of a silhouette ``own`` (T, H, W) not under ``cover``, of ``whole`` pixels (its own area)."""
    seen = own if cover is None else own * (1 - cover)
    return seen.sum((1, 2)) / np.maximum(own.sum((1, 2)) if whole is None else whole, 1.0)


def _in_view(points: np.ndarray, cover: np.ndarray | None, size: tuple[int, int]) -> np.ndarray:
    """Landmarks (T, 33, 3) pixels with their third column set to whether each lies in the picture (``size``) and
    not under ``cover`` (T, H, W)."""
    width, height = size
    x, y = (np.nan_to_num(points[..., k], nan=-1.0).round().astype(int) for k in (0, 1))
    inside = (x >= 0) & (x < width) & (y >= 0) & (y < height)
    if cover is not None:
        at = cover[np.arange(len(points))[:, None], y.clip(0, height - 1), x.clip(0, width - 1)] > 0.5
        inside &= ~at
    out = points.copy()
    out[..., 2] = np.where(np.isfinite(points[..., 0]), inside, np.nan)
    return out


def near_crop(video: Path, out: Path, count: int | None = None) -> Truth:
    """The two-person take cropped around the person nearest the camera (the tallest) and scaled by 1.5: the box
    of their landmarks over the clip, widened by a tenth of their height (a third above their head), then to the
    frame's aspect. The other person, beyond, is cut by the crop's edges. ``count``: the first frames only."""
    frames, fps = read(video, count)
    people = tracked(frames, fps, 2)
    tall = np.nanmax(people[..., 1], 2) - np.nanmin(people[..., 1], 2)
    nearest = int(np.argmax(np.nanmedian(tall, 1)))
    near = people[nearest]
    pad = 0.1 * np.nanmax(tall)
    x0, y0 = np.nanmin(near[..., 0]) - pad, np.nanmin(near[..., 1]) - 3.3 * pad
    x1, y1 = np.nanmax(near[..., 0]) + pad, np.nanmax(near[..., 1]) + pad
    height, width = frames[0].shape[:2]
    grow = (y1 - y0) * width / height - (x1 - x0)  # the frame's aspect: wider (or taller), about the centre
    x0, x1 = (x0 - grow / 2, x1 + grow / 2) if grow > 0 else (x0, x1)
    y0, y1 = (y0 + grow * height / width / 2, y1 - grow * height / width / 2) if grow < 0 else (y0, y1)
    x0, y0, x1, y1 = (int(round(v)) for v in (max(x0, 0.0), max(y0, 0.0), min(x1, width), min(y1, height)))
    scale = 1.5
    size = (int(round((x1 - x0) * scale)) // 2 * 2, int(round((y1 - y0) * scale)) // 2 * 2)
    move = np.array([[scale, 0, -x0 * scale], [0, scale, -y0 * scale]])
    write([cv2.warpAffine(f, move, size, flags=cv2.INTER_LINEAR) for f in frames], fps, out)
    masks = [silhouettes(frames, p) for p in people]  # in the whole frame: what the crop leaves out counts
    window = np.zeros((height, width), np.float32)
    window[y0:y1, x0:x1] = 1
    seen = [_share(m * window, None if k == nearest else masks[nearest], m.sum((1, 2))) for k, m in enumerate(masks)]
    outside = 1 - np.broadcast_to(window, masks[nearest].shape)
    moved = np.stack([_in_view(p, outside if k == nearest else np.maximum(outside, masks[nearest]), (width, height))
                      for k, p in enumerate(people)])
    moved[..., :2] = people[..., :2] * scale + move[:, 2]
    return Truth(moved, np.stack(seen) >= MIN_SHARE)


def pasted(video: Path, out: Path, front: bool, count: int | None = None) -> Truth:
    """The take with a second person in ``front`` of its own or behind them (module docstring); ``count``: its
    first frames only."""
    frames, fps = read(video, count)
    person = tracked(frames, fps, 1)[0]
    mask = silhouettes(frames, person)
    height, width = frames[0].shape[:2]
    tall = float(np.nanmedian(np.nanmax(person[..., 1], 1) - np.nanmin(person[..., 1], 1)))
    centre = np.nanmedian(person[:, [23, 24], :2].reshape(-1, 2), 0)
    side = 1.0 if centre[0] < width / 2 else -1.0  # towards the wider part of the frame
    scale = NEAR_SCALE if front else FAR_SCALE
    shift = np.array([side * OFFSET_HEIGHTS * tall, (1 if front else -1) * DROP_HEIGHTS * tall])
    move = np.hstack([scale * np.eye(2), (centre + shift - scale * centre)[:, None]])
    copies = [cv2.warpAffine(f, move, (width, height), flags=cv2.INTER_LINEAR) for f in frames[::-1]]
    copy_masks = np.stack([cv2.warpAffine(m, move, (width, height), flags=cv2.INTER_LINEAR) for m in mask[::-1]])
    copy_points = person[::-1].copy()
    copy_points[..., :2] = person[::-1, :, :2] * scale + move[:, 2]
    made = []
    for frame, copy, own, other in zip(frames, copies, mask, copy_masks):
        alpha = (other if front else other * (1 - own))[..., None]
        made.append((frame * (1 - alpha) + copy * alpha).round().astype(np.uint8))
    write(made, fps, out)
    copy_whole = scale**2 * mask[::-1].sum((1, 2))  # the copy's area, the frame's edges uncut
    seen = (_share(mask, copy_masks if front else None), _share(copy_masks, None if front else mask, copy_whole))
    points = (_in_view(person, copy_masks if front else None, (width, height)),
              _in_view(copy_points, None if front else mask, (width, height)))
    return Truth(np.stack(points), np.stack(seen) >= MIN_SHARE)


def body25(landmarks: np.ndarray) -> np.ndarray:
    """(T, 25, 3) BODY_25 pixels and a confidence from (T, 33, 3) BlazePose landmarks (pixels and visibility, or a
    truth's in-view flags); zeros where unknown."""
    from jaxmocap.detect.openpose import body25_from_blazepose

    out = np.zeros((len(landmarks), 25, 3))
    for t, points in enumerate(landmarks):
        if np.isfinite(points[:, :2]).all():
            out[t] = body25_from_blazepose(np.concatenate([points[:, :2], np.zeros((33, 1)), points[:, 2:]], 1))
    return np.nan_to_num(out)


def gap_heights(keypoints: np.ndarray, truth: np.ndarray) -> float:
    """The mean distance of BODY_25 ``keypoints`` (25, 3) from where a person is seen (``truth`` (25, 3), `body25`
    of their truth: the points in view), in the person's heights; the smaller of the two readings of left and
    right; inf when either is missing."""
    known = truth[:, 2] > 0
    if not keypoints[:, 2].any() or known.sum() < 4:
        return np.inf
    height = np.ptp(truth[truth[:, 0] != 0, 1]) or 1.0
    gaps = [np.inf]
    for order in (np.arange(25), BODY25_EXCHANGED):
        both = known & (keypoints[order, 2] > 0)
        if both.any():
            gaps.append(np.linalg.norm(keypoints[order][both, :2] - truth[both, :2], axis=1).mean())
    return float(min(gaps) / height)


def followed(keypoints: dict[int, np.ndarray], truth: Truth) -> dict:
    """How identities followed the people of a stand-in: ``keypoints`` (T, 25, 3) BODY_25 of each identity (zeros
    where absent). In each frame each identity is paired with at most one person, among those within
    `MATCH_HEIGHTS` (`gap_heights`), the nearest (`assignment.gated_pairs`). Per person: the frames seen, those
    tracked, and the frames by identity; and the identities paired with more than one person."""
    from jaxmocap.detect.assignment import gated_pairs

    truths, ids = [body25(points) for points in truth.landmarks], list(keypoints)
    by = [dict() for _ in truths]
    for t in range(truth.seen.shape[1]):
        cost = np.array([[gap_heights(keypoints[i][t], person[t]) for person in truths] for i in ids])
        for row, k in gated_pairs(np.where(cost < MATCH_HEIGHTS, cost, np.inf).reshape(len(ids), len(truths))):
            if truth.seen[k, t]:
                by[k][ids[row]] = by[k].get(ids[row], 0) + 1
    on_both = sorted(i for i in ids if sum(i in b for b in by) > 1)
    return dict(ids=len(ids), on_both=on_both, people=[
        dict(seen=int(truth.seen[k].sum()), tracked=sum(by[k].values()), by=by[k]) for k in range(len(truths))])


def turned(video: Path, truth: Truth, kind: str, out: Path) -> Truth:
    """The stand-in ``mirror``ed (left for right) or turned by 90 degrees clockwise (``rotate90``), and its truth."""
    frames, fps = read(video)
    height, width = frames[0].shape[:2]
    points = truth.landmarks.copy()
    if kind == "mirror":
        write([cv2.flip(f, 1) for f in frames], fps, out)
        points[..., 0] = width - 1 - truth.landmarks[..., 0]
    elif kind == "rotate90":
        write([cv2.rotate(f, cv2.ROTATE_90_CLOCKWISE) for f in frames], fps, out)
        points[..., 0], points[..., 1] = height - 1 - truth.landmarks[..., 1], truth.landmarks[..., 0]
    else:
        raise ValueError(f"kind must be mirror or rotate90, got {kind!r}")
    return Truth(points, truth.seen)
