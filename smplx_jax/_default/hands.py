"""Hand pose space: a relaxed mean hand and a PCA of synthetic, anatomically correlated hand poses."""

import numpy as np

from .skeleton import thumb_frame

# SMPL-X finger order within a hand: index, middle, pinky, ring, thumb (3 joints each)
_SPREAD = {"index": 1.0, "middle": 0.15, "pinky": -1.1, "ring": -0.5}
_ORDER = ("index", "middle", "pinky", "ring")


def _right_axes():
    flex = np.array([0.0, 0.0, 1.0])      # curls right-hand fingers (pointing -x) towards the palm (-y)
    spread = np.array([0.0, 1.0, 0.0])    # turns them towards the thumb side (+z)
    d, _ = thumb_frame(-1)
    m = np.array([0.0, -1.0, -0.5])
    t_flex = np.cross(d, m)
    t_flex /= np.linalg.norm(t_flex)
    t_opp = np.cross(d, np.array([0.0, -1.0, 0.3]))
    t_opp /= np.linalg.norm(t_opp)
    return flex, spread, t_flex, t_opp, d


def synthetic_right_poses(n=3000, seed=0):
    rng = np.random.default_rng(seed)
    flex, spread, t_flex, t_opp, _d = _right_axes()
    poses = np.zeros((n, 15, 3))
    close = rng.beta(1.3, 2.2, n)                       # 0 open .. 1 fist, mostly relaxed
    spread_amt = rng.normal(0.0, 0.12, n) + 0.08 * (1 - close)
    for name in _ORDER:
        own = np.clip(close + rng.normal(0, 0.12, n) * (1.0 + 0.5 * (name in ("ring", "pinky"))), -0.1, 1.1)
        base = (0.15 + 0.08 * ("pinky" == name) + 0.05 * (name == "ring"))  # relaxed curl grows to the pinky
        mcp = (base + 1.25 * own)[:, None] * flex + (_SPREAD[name] * spread_amt * (1 - 0.7 * own))[:, None] * spread
        pip = (base + 0.10 + 1.45 * own)[:, None] * flex
        dip = (0.08 + 0.85 * own + rng.normal(0, 0.05, n))[:, None] * flex
        j = 3 * ["index", "middle", "pinky", "ring"].index(name)
        poses[:, j], poses[:, j + 1], poses[:, j + 2] = mcp, pip, dip
    opp = np.clip(0.5 * close + rng.normal(0.15, 0.25, n), -0.3, 1.2)
    poses[:, 12] = opp[:, None] * 0.7 * t_opp + (0.1 + 0.2 * close)[:, None] * t_flex
    poses[:, 13] = (0.10 + 0.55 * close + rng.normal(0, 0.1, n))[:, None] * t_flex
    poses[:, 14] = (0.12 + 0.75 * close + rng.normal(0, 0.1, n))[:, None] * t_flex
    poses = poses.reshape(n, 45) + rng.normal(0, 0.02, (n, 45))
    return poses


def mirror(x):
    """Right-hand axis-angles (..., 45) to the left hand: y and z components negated."""
    x = np.array(x, float).reshape(x.shape[:-1] + (15, 3))
    x[..., 1:] *= -1
    return x.reshape(x.shape[:-2] + (45,))


def hand_pca():
    """(mean_l, components_l, mean_r, components_r); components are orthonormal rows by variance."""
    poses = synthetic_right_poses()
    mean = poses.mean(0)
    cov = np.cov((poses - mean).T)
    _vals, vecs = np.linalg.eigh(cov)
    comps = vecs[:, ::-1].T.copy()
    flex_cols = np.arange(45).reshape(15, 3)[:12, 2]
    for c in comps:  # sign: the first components close the hand (positive flexion)
        ref = c[flex_cols].sum()
        if abs(ref) < 1e-6:
            ref = c[np.argmax(np.abs(c))]
        if ref < 0:
            c *= -1
    return mirror(mean), mirror(comps), mean, comps
