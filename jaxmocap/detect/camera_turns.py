"""How a camera turns from frame to frame, from the background (`CameraTurns`): points of the scene outside the
people's boxes, tracked by OpenCV (Shi-Tomasi corners, pyramidal Lucas-Kanade), seen through the lens as rays.

A camera that turns about its centre (panning, tilting, a hand holding it) moves every ray of the scene by one
rotation, whatever the point's depth: a frame's rays ``b`` are ``R b_key`` of a keyframe's. Points are tracked from
the keyframe itself (each frame's positions the guess for the next), so a still camera's turn stays zero and a
turning one's does not drift between keyframes; the rotation is the best one (Kabsch) over the points that agree
with the best of `TRIALS` pairs (RANSAC) to `AGREE_PX`. A new keyframe is taken where fewer than `KEEP_SHARE` of its
points are still seen. A camera that also travels moves near points across far ones (parallax): the tracked points'
median stray from the best rotation (``background_px``) says so; its travel is not modelled.
"""

from typing import NamedTuple

import cv2
import numpy as np
from jaxtyping import Float

MAX_SIDE = 640  # frames are tracked at most this large (pixels): a turn is a shift of the whole frame, which Lucas-
# Kanade finds to a tenth of a pixel at any size
CORNERS = 300  # points tracked from a keyframe
CORNER_QUALITY = 0.01  # of the strongest corner's (OpenCV's usual)
CORNER_SPACING = 0.03  # of the tracked frame's long side: points spread over the whole background
BOX_MARGIN = 0.2  # of a person's box on each side: their outline (hair, clothes, shadow) reaches past their keypoints
ROUND_TRIP_PX = 0.5  # a point tracked to the frame and back lands this close to where it started, or is dropped
AGREE_PX = 2.0  # a point agrees with a rotation within this (tracked frame pixels): Lucas-Kanade's tenth of a pixel,
# a rolling shutter's and a lens's distortion's pixel or so across the frame
MIN_POINTS = 8  # points that must agree: two fix a rotation, eight spread over the frame do not agree by chance
KEEP_SHARE = 0.5  # of a keyframe's points still seen, or a new keyframe
TRIALS = 200  # RANSAC's pairs of points
# tracked frame pixels: a turn explains the background to Lucas-Kanade's tenth of a pixel and a lens's distortion;
# where half its points stray by half the agreement (`AGREE_PX`) before a new keyframe, its points at different
# depths move apart: the camera travels
TRAVEL_PX = AGREE_PX / 2
WINDOW = (21, 21)  # Lucas-Kanade's window and pyramid levels (OpenCV's usual)
LEVELS = 3


class Keyframe(NamedTuple):
    """The frame points are tracked from: its gray image (tracked size), its points, their last positions, and its
    camera's turn into the scene's axes (axis-angle)."""

    image: np.ndarray
    points: np.ndarray  # (N, 2)
    guesses: np.ndarray  # (N, 2)
    turn: np.ndarray  # (3,)


def rays(points: Float[np.ndarray, "N 2"], focal: float, centre) -> Float[np.ndarray, "N 3"]:
    """Unit rays through ``points`` (pixels) in the camera's axes."""
    out = np.concatenate([(points - np.asarray(centre)) / focal, np.ones((len(points), 1))], 1)
    return out / np.linalg.norm(out, axis=1, keepdims=True)


def kabsch(a: Float[np.ndarray, "*S N 3"], b: Float[np.ndarray, "*S N 3"]) -> Float[np.ndarray, "*S 3 3"]:
    """The rotation ``R`` that best takes ``a`` onto ``b`` (least squares, no reflection), of each stack."""
    u, _, vt = np.linalg.svd(np.swapaxes(b, -1, -2) @ a)
    sign = np.ones(u.shape[:-1])
    sign[..., 2] = np.sign(np.linalg.det(u @ vt))
    return (u * sign[..., None, :]) @ vt


def rotation_between(before: Float[np.ndarray, "N 3"], after: Float[np.ndarray, "N 3"], agree_rad: float, seed: int = 0
                     ) -> tuple[np.ndarray | None, np.ndarray]:
    """``(R, agreeing)``: the rotation taking the rays ``before`` onto ``after`` that most of them agree with
    (within ``agree_rad``; RANSAC over pairs, refined on those), or None where fewer than `MIN_POINTS` do."""
    if len(before) < MIN_POINTS:
        return None, np.zeros(len(before), bool)
    pairs = np.random.default_rng(seed).integers(0, len(before), (TRIALS, 2))
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    rotations = kabsch(before[pairs], after[pairs])  # (S, 3, 3)
    agreeing = np.linalg.norm(np.einsum("sij,nj->sni", rotations, before) - after, axis=-1) < agree_rad
    best = agreeing[np.argmax(agreeing.sum(1))] if len(pairs) else np.zeros(len(before), bool)
    if best.sum() < MIN_POINTS:
        return None, best
    rotation = kabsch(before[best], after[best])
    agreeing = np.linalg.norm(before @ rotation.T - after, axis=1) < agree_rad
    return (kabsch(before[agreeing], after[agreeing]), agreeing) if agreeing.sum() >= MIN_POINTS else (None, best)


def background_mask(shape: tuple[int, int], boxes: Float[np.ndarray, "P 4"], scale: float) -> np.ndarray:
    """``(H, W) uint8``: 255 outside the people's boxes (pixels of the source, ``x0, y0, x1, y1``; NaN: none), each
    widened by `BOX_MARGIN` on every side, at ``scale`` times the source."""
    mask = np.full(shape, 255, np.uint8)
    for box in np.asarray(boxes, np.float64).reshape(-1, 4):
        if np.all(np.isfinite(box)):
            margin = BOX_MARGIN * (box[2:] - box[:2])
            x0, y0 = np.floor((box[:2] - margin) * scale).astype(int)
            x1, y1 = np.ceil((box[2:] + margin) * scale).astype(int)
            mask[max(y0, 0):max(y1, 0), max(x0, 0):max(x1, 0)] = 0
    return mask


class CameraTurns:
    """Each frame's camera turned into the scene's axes (those of the first frame's camera), frame after frame
    (`turns`), through the lens ``(focal_length, principal_point)`` of the source's pixels; what it carries from
    frame to frame is `state` / `restore` (a resumed run goes on as an uninterrupted one)."""

    def __init__(self, lens):
        self.focal, self.centre = float(lens[0]), np.asarray(lens[1], np.float64)
        self.key: Keyframe | None = None
        self.last = np.zeros(3)

    def turns(self, frames: list[np.ndarray], boxes: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        """``(scene_from_camera (n, 3), background_px (n,))`` of ``frames`` (BGR, in order, after those seen
        before), ``boxes[k] (P, 4)`` the people's boxes in frame k: each frame's camera turned into the scene's
        axes (axis-angle; the frame before's where too few points agree), and how far the background's tracked
        points stray from that turn (median, pixels of the source; NaN where too few agree)."""
        turns, spread = [], []
        for frame, frame_boxes in zip(frames, boxes):
            turn, px = self._one(frame, frame_boxes)
            turns.append(turn)
            spread.append(px)
        return np.asarray(turns, np.float32).reshape(-1, 3), np.asarray(spread, np.float32)

    def _one(self, frame: np.ndarray, boxes: np.ndarray) -> tuple[np.ndarray, float]:
        """One frame's turn and the background's stray (`turns`)."""
        scale = min(1.0, MAX_SIDE / max(frame.shape[:2]))
        gray = cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY) if frame.ndim == 3 else frame
        if scale < 1.0:
            gray = cv2.resize(gray, (round(gray.shape[1] * scale), round(gray.shape[0] * scale)),
                              interpolation=cv2.INTER_AREA)
        mask = background_mask(gray.shape, boxes, scale)
        if self.key is None:
            self.key = self._keyframe(gray, mask, self.last)
            return self.last.copy(), np.nan
        key, spread = self.key, np.nan
        focal, centre = self.focal * scale, self.centre * scale
        seen = np.zeros(len(key.points), bool)
        if len(key.points):
            tracked, status, _ = cv2.calcOpticalFlowPyrLK(
                key.image, gray, key.points.astype(np.float32), key.guesses.astype(np.float32).copy(),
                winSize=WINDOW, maxLevel=LEVELS, flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
            back, back_status, _ = cv2.calcOpticalFlowPyrLK(
                gray, key.image, tracked, key.points.astype(np.float32).copy(), winSize=WINDOW, maxLevel=LEVELS,
                flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
            inside = np.clip(np.round(tracked).astype(int), 0, [gray.shape[1] - 1, gray.shape[0] - 1])
            seen = (status[:, 0] == 1) & (back_status[:, 0] == 1) & (
                np.linalg.norm(back - key.points, axis=1) < ROUND_TRIP_PX) & (mask[inside[:, 1], inside[:, 0]] > 0)
            self.key = key._replace(guesses=np.where(seen[:, None], tracked, key.guesses))
            camera_from_key, agreeing = rotation_between(rays(key.points[seen], focal, centre),
                                                         rays(tracked[seen], focal, centre), AGREE_PX / focal)
            if camera_from_key is not None:
                scene_from_key = cv2.Rodrigues(np.asarray(key.turn, np.float64))[0]
                self.last = cv2.Rodrigues(scene_from_key @ camera_from_key.T)[0].ravel()
                moved = rays(key.points[seen], focal, centre) @ camera_from_key.T
                pixels = focal * moved[:, :2] / np.maximum(moved[:, 2:], 1e-6) + centre
                spread = float(np.median(np.linalg.norm(pixels - tracked[seen], axis=1))) / scale
                seen = seen.copy()
                seen[seen] = agreeing
        if seen.sum() < KEEP_SHARE * len(key.points) or seen.sum() < MIN_POINTS:
            self.key = self._keyframe(gray, mask, self.last)
        return self.last.copy(), spread

    @staticmethod
    def _keyframe(gray: np.ndarray, mask: np.ndarray, turn: np.ndarray) -> Keyframe:
        corners = cv2.goodFeaturesToTrack(gray, CORNERS, CORNER_QUALITY, CORNER_SPACING * max(gray.shape), mask=mask)
        points = np.zeros((0, 2)) if corners is None else corners.reshape(-1, 2).astype(np.float64)
        return Keyframe(gray, points, points.copy(), np.asarray(turn, np.float64))

    def state(self) -> dict[str, np.ndarray]:
        """What carries on to the next frames, as arrays."""
        if self.key is None:
            return {"last": self.last.copy()}
        return {"last": self.last.copy()} | {f"key_{k}": np.asarray(v) for k, v in self.key._asdict().items()}

    def restore(self, state: dict[str, np.ndarray]) -> None:
        self.last = np.asarray(state.get("last", np.zeros(3)), np.float64)
        self.key = Keyframe(*(np.asarray(state[f"key_{k}"]) for k in Keyframe._fields)) if "key_image" in state \
            else None


def camera_motion(scene_from_camera: Float[np.ndarray, "T 3"], background_px: Float[np.ndarray, "T"],
                  long_side: float) -> str:
    """The run summary's line on the camera (of frames of ``long_side`` pixels): how far it turned from the first
    frame, how closely a turn explains the background, and whether it seems to travel too (the background's median
    stray beyond `TRAVEL_PX` of the tracked frame: its points at different depths move apart)."""
    angle = float(np.degrees(np.linalg.norm(np.asarray(scene_from_camera), axis=1).max(initial=0.0)))
    measured = np.isfinite(background_px)
    if not measured.any():
        return f"camera: turned up to {angle:.1f} deg from the first frame (too little background to see it)"
    stray = float(np.median(np.asarray(background_px)[measured]))
    line = f"camera: turned up to {angle:.1f} deg from the first frame; the background within {stray:.1f} px of a turn"
    if stray * min(1.0, MAX_SIDE / long_side) > TRAVEL_PX:
        line += " (median): it seems to travel too, which is not modelled (the world frame holds its turns alone)"
    return line
