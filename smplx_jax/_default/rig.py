"""Rigging of the generated surface: skinning weights, the joint regressor and the vertex-joint ids."""

import numpy as np

from .skeleton import FINGERS, PARENTS
from .subdiv import edges_of

SIDE_JOINTS = {  # (hip, knee, ankle, foot, collar, shoulder, elbow, wrist, first finger joint)
    1: (1, 4, 7, 10, 13, 16, 18, 20, 25), -1: (2, 5, 8, 11, 14, 17, 19, 21, 40)}


def _segment_distance(p, a, b):
    ab = b - a
    t = np.clip(((p - a) @ ab) / max(ab @ ab, 1e-12), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def bones(J, tips):
    """Bone segment (start, end) driven by each joint."""
    seg = {}
    children = {j: [c for c in range(55) if PARENTS[c] == j] for j in range(55)}
    for j in range(55):
        kids = children[j]
        if j in tips:
            seg[j] = (J[j], tips[j])
        elif kids:
            seg[j] = (J[j], np.mean([J[c] for c in kids], 0) if j not in (9, 15) else J[kids[0]])
        else:
            seg[j] = (J[j], J[j])
    seg[0] = (J[0], J[3])
    seg[9] = (J[9], J[12])
    return seg


def candidates(part):
    """Joints a vertex of ``part`` may be bound to, with a distance penalty (metres)."""
    if part == "torso":
        return {0: 0, 3: 0, 6: 0, 9: 0, 13: 0.01, 14: 0.01, 1: 0.025, 2: 0.025, 12: 0.03}
    if part == "neck":
        return {12: 0, 9: 0.02, 15: 0.02}
    if part in ("head", "l_ear", "r_ear"):
        return {15: 0}
    s = 1 if part.startswith("l_") else -1
    hip, knee, ankle, foot, collar, sh, el, wr, f0 = SIDE_JOINTS[s]
    name = part[2:]
    if name == "arm":
        return {collar: 0.0, sh: 0, el: 0, wr: 0}
    if name == "hand":
        return {wr: 0}
    if name == "leg":
        return {hip: 0, knee: 0, ankle: 0, 0: 0.02}
    if name == "foot":
        return {ankle: 0, foot: 0}
    n = FINGERS.index(name)
    return {wr: 0.004, f0 + 3 * n: 0, f0 + 3 * n + 1: 0, f0 + 3 * n + 2: 0}


def neighbours(faces, n):
    edges, _ = edges_of(faces)
    deg = np.bincount(edges.ravel(), minlength=n).astype(float)
    return edges, deg


def smooth(values, edges, deg, iterations, alpha=0.5):
    """``iterations`` steps of graph diffusion of the columns of ``values`` (only the nonzero columns)."""
    n = len(values)
    rows = np.concatenate([edges[:, 0], edges[:, 1], np.arange(n)])
    cols = np.concatenate([edges[:, 1], edges[:, 0], np.arange(n)])
    vals = np.concatenate([alpha / deg[edges[:, 0]], alpha / deg[edges[:, 1]], np.full(n, 1 - alpha)])
    used = np.where(np.abs(values).sum(0) > 0)[0]
    out = values.copy()
    for c in used:
        x = values[:, c]
        for _ in range(iterations):
            x = np.bincount(rows, weights=vals * x[cols], minlength=n)
        out[:, c] = x
    return out


def skinning_weights(v, faces, vertex_part, part_names, J, tips, jaw_mask):
    """Closest-bone labels inside each body part, diffused over the mesh, sparsified (<= 4 joints)."""
    n = len(v)
    seg = bones(J, tips)
    label = np.zeros(n, int)
    for code, part in enumerate(part_names):
        ids = np.where(vertex_part == code)[0]
        cand = candidates(part)
        dist = np.stack([_segment_distance(v[ids], *seg[j]) + pen for j, pen in cand.items()], 1)
        label[ids] = np.array(list(cand))[np.argmin(dist, 1)]
    label[jaw_mask] = 22
    W = np.zeros((n, 55))
    W[np.arange(n), label] = 1.0
    edges, deg = neighbours(faces, n)
    W = smooth(W, edges, deg, 10)
    # a joint of one side never moves the other side (no leakage between the legs)
    side = np.zeros(55)
    side[[1, 4, 7, 10, 13, 16, 18, 20] + list(range(25, 40))] = 1
    side[[2, 5, 8, 11, 14, 17, 19, 21] + list(range(40, 55))] = -1
    W[(v[:, 0:1] * side[None, :]) < -0.005] = 0.0
    # sparsify: four largest, drop below 2 %, renormalise
    keep = np.argsort(-W, 1)[:, :4]
    S = np.zeros_like(W)
    rows = np.arange(n)[:, None]
    S[rows, keep] = W[rows, keep]
    S[S < 0.02] = 0.0
    return S / S.sum(1, keepdims=True)


def fit_weights(points, target, iterations=30):
    """Nonnegative weights summing to one with ``weights @ points == target``, closest to uniform."""
    n = len(points)
    active = np.ones(n, bool)
    w = np.zeros(n)
    for _ in range(iterations):
        P = points[active]
        A = np.concatenate([P.T, np.ones((1, len(P)))], 0)
        b = np.concatenate([target, [1.0]])
        w0 = np.full(len(P), 1.0 / len(P))
        lam = np.linalg.lstsq(A @ A.T, b - A @ w0, rcond=None)[0]
        wa = w0 + A.T @ lam
        if wa.min() >= 0:
            w[:] = 0
            w[active] = wa
            return w
        idx = np.where(active)[0]
        active[idx[wa < 0]] = False
        if active.sum() < 4:
            break
    # fall back: the closest convex combination (Frank-Wolfe on the simplex with exact line search)
    w = np.full(n, 1.0 / n)
    for _ in range(3000):
        r = w @ points - target
        i = int(np.argmin(points @ r))
        d = points[i] - w @ points
        step = np.clip(-(r @ d) / max(d @ d, 1e-18), 0.0, 1.0)
        w *= 1 - step
        w[i] += step
    return w


def farthest_sample(points, k):
    if len(points) <= k:
        return np.arange(len(points))
    chosen = [int(np.argmin(np.linalg.norm(points - points.mean(0), axis=1)))]
    d = np.linalg.norm(points - points[chosen[0]], axis=1)
    for _ in range(k - 1):
        chosen.append(int(np.argmax(d)))
        d = np.minimum(d, np.linalg.norm(points - points[chosen[-1]], axis=1))
    return np.array(chosen)


def joint_regressor(v, support, J, count=24):
    """Sparse rows: joint j = a convex combination of ``count`` vertices from ``support[j]`` (ids)."""
    R = np.zeros((55, len(v)))
    for j in range(55):
        ids = np.asarray(support[j])
        ids = ids[farthest_sample(v[ids], count)]
        R[j, ids] = fit_weights(v[ids], J[j])
    return R
