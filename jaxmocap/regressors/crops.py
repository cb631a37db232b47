"""Crops as FrankMocap's reference makes them, for many boxes (of many frames) at once, and the maps from a
crop's weak-perspective camera back to image pixels.

Images are uint8 BGR ``(F, H, W, 3)`` as OpenCV reads them; boxes are ``(x, y, w, h)`` in pixels. A crop is a
`Window`: the integer region of the image that is resized to 224x224 (bilinear, OpenCV's pixel-centre
convention), inside which only ``content`` holds image pixels and the rest is zero.
"""

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float, Int, UInt8

SIZE = 224
IMAGENET_MEAN = np.array([0.485, 0.456, 0.406], np.float32)  # RGB
IMAGENET_STD = np.array([0.229, 0.224, 0.225], np.float32)
BODY_SCALE, HAND_MARGIN, MIN_BODY_CROP = 1.2, 0.3, 20


class Window(NamedTuple):
    """Where each of N crops lies in its image (module docstring): the region resized to ``SIZE`` x ``SIZE`` and
    the part of it that holds image pixels."""

    origin: Int[np.ndarray, "N 2"]  # image pixel of the region's top-left (may be negative)
    size: Int[np.ndarray, "N 2"]  # region (width, height), resized to SIZE x SIZE
    content: Int[np.ndarray, "N 4"]  # x0, y0, x1, y1 (exclusive) of the image pixels kept; zeros elsewhere
    ok: Bool[np.ndarray, "N"]  # False where the reference gives no crop (too small / empty)

    @property
    def ratio(self) -> Float[Array, "N"]:
        """Crop pixels per image pixel (FrankMocap's ``boxScale_o2n``: 224 / region height)."""
        return SIZE / jnp.maximum(jnp.asarray(self.size)[:, 1], 1)


def _boxes(boxes, name: str) -> np.ndarray:
    boxes = np.asarray(boxes, np.float64)
    if boxes.ndim != 2 or boxes.shape[1] != 4:
        raise ValueError(f"{name}: expected (N, 4) boxes (x, y, w, h), got shape {boxes.shape}")
    if not np.all(np.isfinite(boxes)):
        raise ValueError(f"{name}: boxes must be finite (drop missing ones first)")
    return boxes


def body_windows(boxes: Float[np.ndarray, "N 4"], image_size: tuple[int, int]) -> Window:
    """SPIN's crop: a square of side 1.2 max(w, h) about the box centre, corners truncated to integers."""
    boxes = _boxes(boxes, "boxes")
    width, height = image_size
    center = boxes[:, :2] + 0.5 * boxes[:, 2:]
    side = BODY_SCALE * boxes[:, 2:].max(axis=1)
    # The reference maps the crop's corners through the inverse of its 3x3 crop transform and truncates; the
    # inverse's rounding decides the truncation at integers, so it is reproduced as is.
    transform = np.zeros((len(boxes), 3, 3))
    transform[:, 0, 0] = transform[:, 1, 1] = SIZE / side
    transform[:, :2, 2] = SIZE * (0.5 - center / side[:, None])
    transform[:, 2, 2] = 1
    corners = np.linalg.inv(transform) @ np.array([[0.0, SIZE], [0.0, SIZE], [1.0, 1.0]])
    top_left, bottom_right = corners[:, :2, 0].astype(int), corners[:, :2, 1].astype(int)
    size = bottom_right - top_left
    content = np.concatenate([np.maximum(top_left, 0), np.minimum(bottom_right, [width, height])], axis=1)
    ok = np.all(size >= MIN_BODY_CROP, axis=1) & np.all(content[:, 2:] >= content[:, :2], axis=1)
    return Window(top_left, np.maximum(size, 1), content, ok)


def hand_windows(boxes: Float[np.ndarray, "N 4"], image_size: tuple[int, int]) -> Window:
    """FrankMocap's hand crop: grow the short side to a square, add 30% of the height each side (both clipped
    to the image), paste at the top-left of a zero square of the longer side."""
    boxes = _boxes(boxes, "boxes")
    limit = np.array(image_size)
    lo = boxes[:, :2].astype(np.int32)
    wh = boxes[:, 2:].astype(np.int32)
    hi = lo + wh
    grow_y = wh[:, 0] > wh[:, 1]
    margin = np.abs(wh[:, 0] - wh[:, 1]) // 2
    axis = np.where(grow_y, 1, 0)
    rows = np.arange(len(boxes))
    lo[rows, axis] = np.maximum(lo[rows, axis] - margin, 0)
    hi[rows, axis] = np.minimum(hi[rows, axis] + margin, limit[axis])
    margin = (HAND_MARGIN * (hi[:, 1] - lo[:, 1])).astype(np.int32)[:, None]
    lo, hi = np.maximum(lo - margin, 0), np.minimum(hi + margin, limit)
    side = np.max(hi - lo, axis=1)
    ok = np.all(hi > lo, axis=1)
    return Window(lo, np.repeat(np.maximum(side, 1)[:, None], 2, axis=1), np.concatenate([lo, hi], axis=1), ok)


def _axis(origin, size, lo, hi):
    """OpenCV INTER_LINEAR source taps along one axis: image indices, weights, and which taps hold content."""
    dst = jnp.arange(SIZE, dtype=jnp.float32)
    src = (dst + 0.5) * (size[:, None] / SIZE) - 0.5
    i0 = jnp.floor(src)
    frac = src - i0
    taps = jnp.stack([jnp.clip(i0, 0, size[:, None] - 1), jnp.clip(i0 + 1, 0, size[:, None] - 1)], -1)
    pixel = taps.astype(jnp.int32) + origin[:, None, None]
    inside = (pixel >= lo[:, None, None]) & (pixel < hi[:, None, None])
    return pixel, jnp.stack([1 - frac, frac], -1) * inside


@jax.jit
def _sample(images, frame, origin, size, content, flip):
    h, w = images.shape[1:3]
    ys, wy = _axis(origin[:, 1], size[:, 1].astype(jnp.float32), content[:, 1], content[:, 3])
    xs, wx = _axis(origin[:, 0], size[:, 0].astype(jnp.float32), content[:, 0], content[:, 2])
    ys, xs = jnp.clip(ys, 0, h - 1), jnp.clip(xs, 0, w - 1)
    f = frame[:, None, None, None, None]
    taps = images[f, ys[:, :, None, :, None], xs[:, None, :, None, :]].astype(jnp.float32)  # N,224,224,2,2,3
    out = jnp.round(jnp.einsum("nyxabc,nya,nxb->nyxc", taps, wy, wx))  # OpenCV returns uint8
    return jnp.where(flip[:, None, None, None], out[:, :, ::-1], out)


def crop(images: UInt8[ArrayLike, "F H W 3"], frame: int | Int[np.ndarray, "N"], window: Window,
         flip: bool | Bool[np.ndarray, "N"] | None = None) -> Float[Array, "N 224 224 3"]:
    """The 0..255 BGR crops of ``window`` from ``images[frame]``; ``flip`` mirrors a crop left-right (``frame``
    and ``flip`` may be one for all)."""
    images = jnp.asarray(images)
    if images.ndim != 4 or images.shape[-1] != 3:
        raise ValueError(f"images: expected (F, H, W, 3) uint8 BGR, got shape {images.shape}")
    n = len(window.origin)
    frame = np.broadcast_to(np.asarray(frame, np.int32), (n,))
    flip = np.zeros(n, bool) if flip is None else np.broadcast_to(np.asarray(flip, bool), (n,))
    return _sample(images, frame, *(np.asarray(a, np.int32) for a in window[:3]), flip)


def normalize_body(crops: Float[ArrayLike, "*batch H W 3"]) -> Float[Array, "*batch H W 3"]:
    """BGR 0..255 -> RGB, ImageNet mean/std (the body network's input)."""
    return (jnp.asarray(crops)[..., ::-1] / 255.0 - IMAGENET_MEAN) / IMAGENET_STD


def normalize_hand(crops: Float[ArrayLike, "*batch H W 3"]) -> Float[Array, "*batch H W 3"]:
    """BGR kept, (x/255 - 0.5)/0.5 (the hand network's input)."""
    return (jnp.asarray(crops) / 255.0 - 0.5) / 0.5


def body_to_image(points: Float[ArrayLike, "N P 3"], camera: Float[ArrayLike, "N 3"], window: Window
                  ) -> Float[Array, "N P 2"]:
    """Pixels of body points: ``((X s) + t) 112 / ratio + top_left + 112 / ratio``."""
    crop_xy = (points[..., :2] * camera[:, None, :1] + camera[:, None, 1:]) * (SIZE / 2)
    return _crop_to_image(crop_xy, window)


def hand_to_image(points: Float[ArrayLike, "N P 3"], camera: Float[ArrayLike, "N 3"], window: Window
                  ) -> Float[Array, "N P 2"]:
    """Pixels of hand points: ``((X + t) s) 112 / ratio + top_left + 112 / ratio``."""
    crop_xy = (points[..., :2] + camera[:, None, 1:]) * camera[:, None, :1] * (SIZE / 2)
    return _crop_to_image(crop_xy, window)


def image_to_crop(points: Float[ArrayLike, "N P 2"], window: Window) -> Float[Array, "N P 2"]:
    """Image pixels -> pixels of the 224x224 crop cut with ``window`` (the inverse of its last step)."""
    origin = jnp.asarray(window.origin, jnp.float32)[:, None, :]
    return (points - origin) * window.ratio.astype(jnp.float32)[:, None, None]


def _crop_to_image(crop_xy, window: Window):
    ratio = window.ratio.astype(jnp.float32)[:, None, None]
    return (crop_xy + SIZE / 2) / ratio + jnp.asarray(window.origin, jnp.float32)[:, None, :]
