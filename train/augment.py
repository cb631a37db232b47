"""Samples -> network-ready examples: FrankMocap's crops with random scale, translation, in-plane rotation, colour
jitter and camera-shake motion blur, labels moved consistently; left hands (and, at random, bodies) mirrored.

Pixel coordinates have their origin at the image's top-left corner (pixel ``i`` spans ``[i, i + 1)``), the
convention in which `jaxmocap.regressors.crops` maps crops back to images (``pixel / ratio + origin``). A crop is
one affine map of such coordinates, done by ONE ``cv2.warpAffine`` (bilinear, zero outside the source region).
With ``rng=None`` the crop is the deterministic evaluation crop, the one `crops.crop` cuts at inference (it reads
only the reference window's ``content``: FrankMocap zero-pads hand windows clipped by the image border); augmented
crops read the whole image around the moved window.
"""

import dataclasses
from typing import NamedTuple

import cv2
import numpy as np
from jaxtyping import Float, UInt8

from jaxmocap.regressors import crops
from train.blur import blur, motion_blur_kernel
from train.datasets.sample import NUM_BODY_JOINTS, NUM_HAND_JOINTS, BodyExample, BodySample, HandExample, HandSample

# left <-> right: BODY_25 (OpenPose) and SMPL-X's 22 body joints (pelvis .. r_wrist)
BODY_25_MIRROR = np.array([0, 1, 5, 6, 7, 2, 3, 4, 8, 12, 13, 14, 9, 10, 11, 16, 15, 18, 17, 22, 23, 24, 19, 20, 21])
SMPLX_BODY_MIRROR = np.array([0, 2, 1, 3, 5, 4, 6, 8, 7, 9, 11, 10, 12, 14, 13, 15, 17, 16, 19, 18, 21, 20])
MIRROR_ROTVEC = np.array([1.0, -1.0, -1.0])  # an axis-angle conjugated by the x flip (left <-> right)


@dataclasses.dataclass(frozen=True)
class AugmentConfig:
    """Random crop and appearance changes (defaults: hands, after SPIN's factors)."""

    scale: float = 0.25  # crop side times U(1 - scale, 1 + scale)
    translate: float = 0.1  # crop centre moved by U(-t, t) crop sides along each axis
    rotate_deg: float = 30.0  # in-plane rotation U(-r, r) degrees ...
    rotate_prob: float = 1.0  # ... drawn with this probability (else 0)
    flip_prob: float = 0.0  # bodies: mirror left-right (hands are always made right hands instead)
    channel_gain: float = 0.4  # per-channel gain U(1 - g, 1 + g), SPIN's pixel noise
    brightness: float = 0.1  # plus U(-b, b) * 255
    contrast: float = 0.2  # about mid-grey, times U(1 - c, 1 + c)
    blur_prob: float = 0.5
    blur_length: tuple[float, float] = (0.02, 0.08)  # shake path length, fraction of the crop side
    blur_exposure: tuple[float, float] = (0.5, 1.0)  # fraction of the path the shutter sees
    blur_anxiety: float = 0.005  # Boracchi & Foi's demo value

    @classmethod
    def body(cls) -> "AugmentConfig":
        """SPIN's body setting: rotation with probability 0.4, random flips."""
        return cls(rotate_prob=0.4, flip_prob=0.5)


class CropMap(NamedTuple):
    """An affine map of image pixels to crop pixels with the in-plane rotation and mirroring it applies."""

    affine: Float[np.ndarray, "3 3"]
    angle: float  # radians: crop content turned by +angle in pixel axes (x right, y down)
    mirror: bool


def rotation_z(angle: float) -> Float[np.ndarray, "3 3"]:
    """Rotation about the camera's z axis that turns projected (x, y) by ``angle`` in pixel axes."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def crop_map(origin: Float[np.ndarray, "2"], side: Float[np.ndarray, "2"], size: int, mirror: bool,
             rng: np.random.Generator | None, config: AugmentConfig) -> CropMap:
    """The window ``[origin, origin + side)`` resized to ``size`` x ``size``, then randomly moved, scaled and
    turned about the crop centre, then mirrored if asked."""
    base = np.diag([size / side[0], size / side[1], 1.0])
    base[:2, 2] = -origin * base[[0, 1], [0, 1]]
    angle, jitter = 0.0, np.eye(3)
    if rng is not None:
        zoom = 1 + rng.uniform(-config.scale, config.scale)
        shift = rng.uniform(-config.translate, config.translate, 2) * size
        rotate = rng.random() < config.rotate_prob
        angle = float(np.deg2rad(rng.uniform(-config.rotate_deg, config.rotate_deg))) if rotate else 0.0
        centre = np.full(2, size / 2)
        jitter[:2, :2] = rotation_z(angle)[:2, :2] / zoom
        jitter[:2, 2] = centre - jitter[:2, :2] @ (centre + shift)
    flip = np.array([[-1.0, 0.0, size], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]) if mirror else np.eye(3)
    return CropMap(flip @ jitter @ base, angle, mirror)


def _colour_lut(rng: np.random.Generator, config: AugmentConfig) -> UInt8[np.ndarray, "256 1 3"]:
    gain = rng.uniform(1 - config.channel_gain, 1 + config.channel_gain, 3)
    contrast = rng.uniform(1 - config.contrast, 1 + config.contrast)
    offset = rng.uniform(-config.brightness, config.brightness) * 255
    levels = 127.5 + contrast * (np.arange(256.0) - 127.5)
    lut = np.clip(np.round(levels[:, None] * gain + offset), 0, 255).astype(np.uint8)
    lut[0] = 0  # black stays black: the zero padding stays what the network sees at inference
    return lut[:, None, :]


def warp(image: UInt8[np.ndarray, "H W 3"], affine: Float[np.ndarray, "3 3"], size: int,
         region: tuple[int, int, int, int]) -> UInt8[np.ndarray, "size size 3"]:
    """``image`` through ``affine`` (corner-origin pixels) into a ``size`` crop, reading only ``region`` (x0, y0,
    x1, y1 exclusive; zero elsewhere)."""
    x0, y0, x1, y1 = region
    if x1 <= x0 or y1 <= y0:
        return np.zeros((size, size, 3), np.uint8)
    source = image[y0:y1, x0:x1]
    linear = affine[:2, :2]
    offset = affine[:2, 2] + linear @ np.array([x0 + 0.5, y0 + 0.5]) - 0.5  # to OpenCV's pixel-index convention
    matrix = np.concatenate([linear, offset[:, None]], axis=1)
    return cv2.warpAffine(source, matrix, (size, size), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)


def _visible_region(affine, size: int, image_size: tuple[int, int]) -> tuple[int, int, int, int]:
    """The image pixels the crop can read: its corners mapped back, widened by one pixel, clipped to the image."""
    corners = np.linalg.inv(affine) @ np.array([[0.0, size, 0.0, size], [0.0, 0.0, size, size], [1.0, 1.0, 1.0, 1.0]])
    lo = np.maximum(np.floor(corners[:2].min(axis=1)).astype(int) - 1, 0)
    hi = np.minimum(np.ceil(corners[:2].max(axis=1)).astype(int) + 1, image_size)
    return int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1])


def _crop_pixels(sample_image, cmap: CropMap, size: int, content, rng, config: AugmentConfig):
    """The evaluation crop reads the window's ``content``; an augmented one whatever of the image it covers."""
    if rng is None:
        return warp(sample_image, cmap.affine, size, tuple(int(v) for v in content))
    crop = warp(sample_image, cmap.affine, size, _visible_region(cmap.affine, size, sample_image.shape[1::-1]))
    crop = cv2.LUT(crop, _colour_lut(rng, config))
    if rng.random() < config.blur_prob:
        length = rng.uniform(*config.blur_length) * size
        kernel = motion_blur_kernel(rng, max(5, int(round(length)) + 3) | 1, rng.uniform(*config.blur_exposure),
                                    config.blur_anxiety)
        crop = blur(crop, kernel)
    return crop


def _points_2d(points, cmap: CropMap, size: int):
    pixels = points @ cmap.affine[:2, :2].T + cmap.affine[:2, 2]
    mask = np.all(np.isfinite(pixels), axis=1)
    return np.where(mask[:, None], pixels / (size / 2) - 1, 0.0).astype(np.float32), mask


def _points_3d(points, cmap: CropMap):
    turned = points @ rotation_z(cmap.angle).T
    if cmap.mirror:
        turned = turned * np.array([-1.0, 1.0, 1.0])
    return _masked(turned)


def _turned(rotvec, angle: float):
    """A global orientation (axis-angle) after the crop's in-plane rotation (mirroring is the caller's)."""
    rotvec = np.asarray(rotvec, np.float64)
    if not np.all(np.isfinite(rotvec)):
        return rotvec
    return cv2.Rodrigues(rotation_z(angle) @ cv2.Rodrigues(rotvec)[0])[0][:, 0]


def _masked(values):
    ok = bool(np.all(np.isfinite(values)))
    return (values if ok else np.zeros_like(values)).astype(np.float32), np.bool_(ok)


_HAND_SHAPES = {"joints_2d": (NUM_HAND_JOINTS, 2), "joints_3d": (NUM_HAND_JOINTS, 3), "wrist_rotvec": (3,),
                "hand_pose": (15, 3)}
_BODY_SHAPES = {"joints_2d": (NUM_BODY_JOINTS, 2), "joints_3d": (NUM_BODY_JOINTS, 3), "global_orient": (3,),
                "body_pose": (21, 3)}


def _check(sample, size: int, shapes: dict[str, tuple[int, ...]]):
    image = sample.image
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 3:
        raise ValueError(f"sample.image: expected (H, W, 3) uint8 BGR, got {getattr(image, 'dtype', None)} "
                         f"{np.shape(image)}")
    for name, shape in ({"box": (4,), "betas": (10,)} | shapes).items():
        if np.shape(getattr(sample, name)) != shape:
            raise ValueError(f"sample.{name}: expected shape {shape}, got {np.shape(getattr(sample, name))}")
    if not np.all(np.isfinite(sample.box)) or sample.box[2] <= 0 or sample.box[3] <= 0:
        raise ValueError(f"sample.box: expected a finite (x, y, w, h) with w, h > 0, got {sample.box}")
    if not isinstance(size, (int, np.integer)) or size < 8:
        raise ValueError(f"size: expected an int >= 8, got {size!r}")


def hand_example(sample: HandSample, size: int, rng: np.random.Generator | None = None,
                 config: AugmentConfig = AugmentConfig()) -> HandExample:
    """The right-hand crop FrankMocap's hand network sees (left hands mirrored), augmented unless ``rng`` is None;
    BGR ``(x/255 - 0.5)/0.5``."""
    _check(sample, size, _HAND_SHAPES)
    height, width = sample.image.shape[:2]
    window = crops.hand_windows(np.asarray(sample.box)[None], (width, height))
    cmap = crop_map(window.origin[0].astype(float), window.size[0].astype(float), size, bool(sample.is_left),
                    rng, config)
    image = _crop_pixels(sample.image, cmap, size, window.content[0], rng, config)
    joints_2d, joints_2d_mask = _points_2d(np.asarray(sample.joints_2d, np.float64), cmap, size)
    joints_3d, joints_3d_mask = _points_3d(np.asarray(sample.joints_3d, np.float64), cmap)
    pose = np.concatenate([_turned(sample.wrist_rotvec, cmap.angle)[None], np.asarray(sample.hand_pose, np.float64)])
    pose, pose_mask = _masked(pose * MIRROR_ROTVEC if sample.is_left else pose)
    betas, betas_mask = _masked(np.asarray(sample.betas, np.float64))
    return HandExample(np.asarray(crops.normalize_hand(image.astype(np.float32)), np.float32), joints_2d,
                       joints_2d_mask, joints_3d, joints_3d_mask, pose, pose_mask, betas, betas_mask)


def body_example(sample: BodySample, size: int, rng: np.random.Generator | None = None,
                 config: AugmentConfig = AugmentConfig.body()) -> BodyExample:
    """SPIN's person crop, augmented (and mirrored with ``config.flip_prob``) unless ``rng`` is None; RGB with
    ImageNet mean/std."""
    _check(sample, size, _BODY_SHAPES)
    height, width = sample.image.shape[:2]
    window = crops.body_windows(np.asarray(sample.box)[None], (width, height))
    if not window.ok[0]:
        raise ValueError(f"sample.box: {sample.box} gives no body crop (side under {crops.MIN_BODY_CROP} px)")
    mirror = rng is not None and rng.random() < config.flip_prob
    cmap = crop_map(window.origin[0].astype(float), window.size[0].astype(float), size, mirror, rng, config)
    image = _crop_pixels(sample.image, cmap, size, window.content[0], rng, config)
    order = BODY_25_MIRROR if mirror else np.arange(NUM_BODY_JOINTS)
    joints_2d, joints_2d_mask = _points_2d(np.asarray(sample.joints_2d, np.float64)[order], cmap, size)
    joints_3d, joints_3d_mask = _points_3d(np.asarray(sample.joints_3d, np.float64)[order], cmap)
    pose = np.concatenate([_turned(sample.global_orient, cmap.angle)[None], np.asarray(sample.body_pose, np.float64)])
    if mirror:
        pose = pose[SMPLX_BODY_MIRROR] * MIRROR_ROTVEC
    pose, pose_mask = _masked(pose)
    betas, betas_mask = _masked(np.asarray(sample.betas, np.float64))
    return BodyExample(np.asarray(crops.normalize_body(image.astype(np.float32)), np.float32), joints_2d,
                       joints_2d_mask, joints_3d, joints_3d_mask, pose, pose_mask, betas, betas_mask)


def example(sample: HandSample | BodySample, size: int, rng: np.random.Generator | None = None,
            config: AugmentConfig | None = None) -> HandExample | BodyExample:
    """`hand_example` or `body_example` by the sample's type (``config`` None: that function's default)."""
    if isinstance(sample, HandSample):
        return hand_example(sample, size, rng, config or AugmentConfig())
    if isinstance(sample, BodySample):
        return body_example(sample, size, rng, config or AugmentConfig.body())
    raise ValueError(f"sample: expected a HandSample or BodySample, got {type(sample).__name__}")
