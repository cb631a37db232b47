"""Camera-shake motion blur: random trajectories and their PSFs after Boracchi & Foi, "Modeling the performance of
image restoration from motion blur" (TIP 2012), as their createTrajectory / createPSFs describe them.

A particle moves with a velocity of constant speed; at each sample the velocity gets a Gaussian kick, a
centripetal pull back towards the start and, rarely, an impulsive jump that roughly reverses it (a button press
or a compensating movement). ``anxiety`` scales all perturbations (0: a straight line). The PSF is the sub-pixel
(bilinear) rasterisation of the part of the trajectory covered by the exposure, normalised to sum 1.
"""

import cv2
import numpy as np
from jaxtyping import Complex, Float, UInt8

_DIRECT = 11  # the largest kernel side OpenCV filters directly
_PAPER_LENGTH = 64.0  # Boracchi & Foi's demo: 64-px trajectories of 2000 samples, anxiety 0.005
_FIXED = 64  # partial sums of the tiles in 1/64 grey levels (255 * 64 fits int16)


def shake_trajectory(rng: np.random.Generator, length: float, anxiety: float = 0.005,
                     samples: int = 2000) -> Complex[np.ndarray, "T"]:
    """Positions (x + iy, pixels, starting at 0) of a random camera-shake path of total length ``length``."""
    if length <= 0 or samples < 2 or anxiety < 0:
        raise ValueError(f"length must be > 0, samples >= 2 and anxiety >= 0, got {length}, {samples}, {anxiety}")
    centripetal, gaussian, big_shakes = 0.7 * rng.random(), 10 * rng.random(), 0.2 * rng.random()
    step = length / (samples - 1)
    velocity = complex(np.exp(2j * np.pi * rng.random()) * (anxiety if anxiety > 0 else step))
    kicks = (rng.standard_normal(samples) + 1j * rng.standard_normal(samples)) * (gaussian * anxiety * step)
    jumps = rng.random(samples) < big_shakes * anxiety
    # an impulsive jump adds 2 v e^{i(pi + U(-1/2, 1/2))}: the velocity roughly reverses
    growth = np.where(jumps, 1 + 2 * np.exp(1j * (np.pi + rng.random(samples) - 0.5)), 1)
    pull = anxiety * centripetal * step
    positions, x = [0j], 0j
    for kick, grow in zip(kicks[:-1].tolist(), growth[:-1].tolist()):  # sequential: the pull depends on x
        velocity = velocity * grow + kick - pull * x
        velocity *= step / abs(velocity)
        x += velocity
        positions.append(x)
    return np.array(positions)


def psf(trajectory: Complex[np.ndarray, "T"], size: int, exposure: float = 1.0) -> Float[np.ndarray, "size size"]:
    """The ``size`` x ``size`` PSF of the first ``exposure`` fraction of ``trajectory``, bilinearly splatted with
    its weighted centroid at the kernel centre (so blurring does not shift the image), shrunk to fit if needed."""
    if size < 3 or size % 2 == 0 or not 0 < exposure <= 1:
        raise ValueError(f"size must be odd >= 3 and exposure in (0, 1], got {size}, {exposure}")
    weight = np.clip(exposure * len(trajectory) - np.arange(len(trajectory)), 0, 1)
    points = trajectory[weight > 0]
    weight = weight[weight > 0]
    points = points - np.sum(points * weight) / np.sum(weight)
    reach = max(np.abs(points.real).max(), np.abs(points.imag).max())
    half = (size - 1) / 2
    if reach > half - 1:
        points = points * ((half - 1) / reach)
    x, y = points.real + half, points.imag + half
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    kernel = np.zeros(size * size)
    for dx, dy, w in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        kernel += np.bincount((y0 + dy) * size + x0 + dx, weight * w, size * size)
    kernel = kernel.reshape(size, size)
    return kernel / kernel.sum()


def motion_blur_kernel(rng: np.random.Generator, size: int, exposure: float = 1.0, anxiety: float = 0.005,
                       samples: int = 2000) -> Float[np.ndarray, "size size"]:
    """A random camera-shake PSF of odd side ``size``: a path drawn at the paper's scale (64 px; the centripetal
    pull is not scale-free) and shrunk to ``size - 3`` px long."""
    if size < 5 or size % 2 == 0:
        raise ValueError(f"size must be odd >= 5, got {size}")
    path = shake_trajectory(rng, _PAPER_LENGTH, anxiety, samples) * ((size - 3) / _PAPER_LENGTH)
    return psf(path, size, exposure)


def blur(image: UInt8[np.ndarray, "H W 3"], kernel: Float[np.ndarray, "K K"]) -> UInt8[np.ndarray, "H W 3"]:
    """``image`` filtered with the odd-sided ``kernel`` centred (replicated borders, rounded back to uint8).

    OpenCV switches to a much slower DFT for kernels over 11x11, so larger ones are applied in 11x11 tiles (empty
    tiles skipped: a shake PSF is thin) to a padded image, each tile's partial sum (int16, in 1/64 grey levels) read
    at its offset."""
    side = kernel.shape[0]
    if side <= _DIRECT:
        return cv2.filter2D(image, -1, kernel.astype(np.float32), borderType=cv2.BORDER_REPLICATE)
    height, width = image.shape[:2]
    half = side // 2
    padded = cv2.copyMakeBorder(image, half, half, half, half, cv2.BORDER_REPLICATE)
    total = np.zeros((height, width, 3), np.int32)
    for y0 in range(0, side, _DIRECT):
        for x0 in range(0, side, _DIRECT):
            tile = kernel[y0:y0 + _DIRECT, x0:x0 + _DIRECT]
            if tile.any():  # anchor (0, 0): output (y, x) sums padded[y + i, x + j]
                part = cv2.filter2D(padded, cv2.CV_16S, (tile * _FIXED).astype(np.float32), anchor=(0, 0),
                                    borderType=cv2.BORDER_REPLICATE)
                total += part[y0:y0 + height, x0:x0 + width]
    return np.clip((total + _FIXED // 2) // _FIXED, 0, 255).astype(np.uint8)
