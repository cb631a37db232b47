"""The head: an implicit base shape (cranium, face, jaw, neck) with sculpted facial features, ray-cast from a
point behind the face. Coordinates are head-local: origin between the ear canals, unscaled metres."""

import numpy as np

RAY_ORIGIN = np.array([0.0, -0.010, 0.030])
EYE = np.array([0.032, 0.012])          # eye centre (x, y); z comes from the surface
MOUTH_Y = -0.0635
EAR = np.array([0.072, 0.0, 0.0])        # ear canal, head-local


def smoothstep(a, b, x):
    t = np.clip((x - a) / (b - a), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _ellipsoid(p, c, r):
    q = (p - c) / r
    k0 = np.linalg.norm(q, axis=-1)
    k1 = np.linalg.norm(q / r, axis=-1)
    return k0 * (k0 - 1.0) / np.maximum(k1, 1e-9)


def _smin(a, b, k):
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b * (1 - h) + a * h - k * h * (1 - h)


def _g(dx, dy, sx, sy):
    return np.exp(-(dx / sx) ** 2 - (dy / sy) ** 2)


def base_sdf(p):
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    cranium = _ellipsoid(p, np.array([0.0, 0.030, -0.014]), np.array([0.076, 0.096, 0.097]))
    # face: narrower towards the chin
    taper = 1.0 - 0.30 * smoothstep(-0.02, -0.10, y)
    q = np.stack([x / taper, y, z], -1)
    face = _ellipsoid(q, np.array([0.0, -0.028, 0.022]), np.array([0.062, 0.077, 0.068]))
    jaw = _ellipsoid(p, np.array([0.0, -0.052, -0.004]), np.array([0.057, 0.045, 0.055]))
    neck = np.maximum(np.maximum(np.hypot(x, (z + 0.028) / 1.05) - 0.047, -(y + 0.110)), y + 0.01)
    d = _smin(cranium, face, 0.022)
    d = _smin(d, jaw, 0.015)
    return _smin(d, neck, 0.022)


def features(p):
    """Outward displacement (metres) of the facial features at head-local points ``p``."""
    x, y, z = p[..., 0], p[..., 1], p[..., 2]
    front = smoothstep(0.025, 0.060, z)
    ax = np.abs(x)
    b = 0.0035 * _g(x, y - 0.030, 0.045, 0.011)                               # brow ridge
    b = b - 0.0100 * _g(ax - EYE[0], y - EYE[1], 0.017, 0.012)               # eye sockets
    b = b + 0.0055 * _g(ax - EYE[0], y - EYE[1], 0.0120, 0.0065)             # eyeballs under the lids
    b = b + 0.0040 * _g(ax - 0.050, y + 0.010, 0.014, 0.013)                 # cheekbones
    t = np.clip((0.012 - y) / 0.040, 0.0, 1.0)                               # nose: bridge -> tip
    h = (0.004 + 0.019 * t ** 1.3) * smoothstep(-0.046, -0.031, y) * (1 - smoothstep(0.010, 0.030, y))
    hw = 0.0075 + 0.0070 * t
    b = b + h * np.exp(-(x / hw) ** 2)
    b = b + 0.0055 * _g(ax - 0.0135, y + 0.0325, 0.0055, 0.0065)             # nostril wings
    lips = np.exp(-(x / 0.026) ** 4)
    b = b + 0.0035 * lips * _g(0, y + 0.0570, 1, 0.0055)                      # upper lip
    b = b + 0.0042 * lips * _g(0, y + 0.0710, 1, 0.0060)                      # lower lip
    b = b - 0.0028 * np.exp(-(x / 0.024) ** 4) * _g(0, y - MOUTH_Y, 1, 0.0030)  # mouth line
    b = b - 0.0025 * np.exp(-(x / 0.020) ** 2) * _g(0, y + 0.0835, 1, 0.0050)  # below the lower lip
    b = b + 0.0050 * _g(x, y + 0.0965, 0.020, 0.011)                          # chin
    return b * front


def sdf(p):
    return base_sdf(p) - features(p)


def cast(dirs, with_features=True, origin=RAY_ORIGIN, near=None, iterations=20):
    """Surface points along rays from ``origin`` (head-local) in directions ``dirs`` (bisection); with
    ``near`` (distances along the rays), only within 4 cm of those."""
    dirs = dirs / np.linalg.norm(dirs, axis=-1, keepdims=True)
    f = sdf if with_features else base_sdf
    if near is None:
        lo, hi = np.zeros(dirs.shape[:-1]), np.full(dirs.shape[:-1], 0.30)
    else:
        lo, hi = np.maximum(near - 0.03, 0.0), near + 0.035
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        inside = f(origin + mid[..., None] * dirs) < 0
        lo = np.where(inside, mid, lo)
        hi = np.where(inside, hi, mid)
    return origin + (0.5 * (lo + hi))[..., None] * dirs


def face_point(x, y):
    """The surface points of the face at (x, y) (arrays)."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    d = np.stack([x, y, np.full(x.shape, 0.10)], -1) - RAY_ORIGIN
    for _ in range(3):  # the ray through (x, y) on the surface, not on a plane
        p = cast(d)
        d = np.stack([x, y, p[..., 2]], -1) - RAY_ORIGIN
    return cast(d)


# The 51 facial landmarks (68-point scheme without the jaw line), subject's right = -x.
_BROW = [(-0.058, 0.025), (-0.047, 0.031), (-0.035, 0.034), (-0.024, 0.033), (-0.012, 0.030)]
_EYE_R = [(-0.047, 0.011), (-0.038, 0.0165), (-0.026, 0.0165), (-0.018, 0.011), (-0.026, 0.0072), (-0.038, 0.0072)]
LANDMARKS_XY = np.array(
    _BROW + [(-x, y) for x, y in _BROW[::-1]]
    + [(0, 0.012), (0, -0.002), (0, -0.015), (0, -0.027)]
    + [(-0.016, -0.035), (-0.008, -0.039), (0, -0.041), (0.008, -0.039), (0.016, -0.035)]
    + _EYE_R + [(-x, y) for x, y in [_EYE_R[3], _EYE_R[2], _EYE_R[1], _EYE_R[0], _EYE_R[5], _EYE_R[4]]]
    + [(-0.025, -0.064), (-0.016, -0.0565), (-0.006, -0.0535), (0, -0.0545), (0.006, -0.0535), (0.016, -0.0565),
       (0.025, -0.064), (0.016, -0.0715), (0.007, -0.0755), (0, -0.076), (-0.007, -0.0755), (-0.016, -0.0715)]
    + [(-0.021, -0.0637), (-0.009, -0.0622), (0, -0.0622), (0.009, -0.0622), (0.021, -0.0637), (0.009, -0.0650),
       (0, -0.0652), (-0.009, -0.0650)])


def expressions(p, normal):
    """Ten expression displacement fields (N, 3, 10) at head-local points ``p`` with unit normals ``normal``."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    front = smoothstep(0.02, 0.06, z)
    ax, sx = np.abs(x), np.sign(x)
    out = np.zeros(p.shape + (10,))
    # 0 mouth open: the lower lip, chin and jaw front move down and slightly back
    below = smoothstep(MOUTH_Y + 0.002, MOUTH_Y - 0.012, y) * np.exp(-(x / 0.05) ** 4) * front
    out[:, 1, 0] = -0.010 * below
    out[:, 2, 0] = -0.003 * below
    # 1 smile: mouth corners up, out and back; cheeks up
    corner = _g(ax - 0.025, y - MOUTH_Y, 0.014, 0.012) * front
    cheek = _g(ax - 0.040, y + 0.035, 0.018, 0.018) * front
    out[:, 0, 1] = 0.004 * sx * corner
    out[:, 1, 1] = 0.005 * corner + 0.003 * cheek
    out[:, 2, 1] = -0.002 * corner + 0.002 * cheek
    # 2 frown: mouth corners down
    out[:, 1, 2] = -0.005 * corner
    # 3 pucker: lips forward and narrower
    lips = _g(x, y - MOUTH_Y, 0.028, 0.014) * front
    out[:, 2, 3] = 0.007 * lips
    out[:, 0, 3] = -0.25 * x * lips
    # 4 brows up
    brow = _g(ax - 0.032, y - 0.031, 0.030, 0.012) * front
    out[:, 1, 4] = 0.005 * brow
    # 5 brows down and together
    inner = _g(ax - 0.018, y - 0.030, 0.016, 0.010) * front
    out[:, 1, 5] = -0.0035 * inner
    out[:, 0, 5] = -0.0020 * np.tanh(x / 0.010) * inner
    # 6 cheeks puffed out
    puff = _g(ax - 0.038, y + 0.045, 0.018, 0.020) * front
    out[:, :, 6] = 0.006 * puff[:, None] * normal
    # 7 eyes squint / close: upper lids down, lower lids up
    upper = _g(ax - EYE[0], y - EYE[1] - 0.006, 0.013, 0.005) * front
    lower = _g(ax - EYE[0], y - EYE[1] + 0.006, 0.013, 0.004) * front
    out[:, 1, 7] = -0.0025 * upper + 0.0010 * lower
    # 8 upper lip raise and nose wrinkle
    ulip = _g(x, y + 0.055, 0.022, 0.010) * front
    out[:, 1, 8] = 0.0035 * ulip
    out[:, 2, 8] = 0.0015 * ulip
    # 9 mouth to the side (subject's left)
    mouth = _g(x, y - MOUTH_Y, 0.035, 0.020) * front
    out[:, 0, 9] = 0.006 * mouth
    return out
