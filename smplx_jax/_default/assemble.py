"""Assemble the SMPL-X arrays: rig, shape and expression spaces, hand PCA, landmarks, vertex-joint ids."""

import numpy as np

from smplx_jax.geometry import vertex_normals

from . import head as hd
from . import rig
from .hands import hand_pca
from .skeleton import FINGERS, PARENTS, SHAPE_PARAMS, params
from .surface import NUM_VERTICES, head_local, surface

VERTEX_JOINT_IDS = {
    "nose": 9120, "reye": 9929, "leye": 9448, "rear": 616, "lear": 6,
    "rthumb": 8079, "rindex": 7669, "rmiddle": 7794, "rring": 7905, "rpinky": 8022,
    "lthumb": 5361, "lindex": 4933, "lmiddle": 5058, "lring": 5169, "lpinky": 5286,
    "LBigToe": 5770, "LSmallToe": 5780, "LHeel": 8846, "RBigToe": 8463, "RSmallToe": 8474, "RHeel": 8635,
}

# Correlations between the anatomical parameters of the synthetic population (others independent).
_CORRELATIONS = {("weight", "belly"): 0.5, ("weight", "chest"): 0.4, ("weight", "hips"): 0.35,
                 ("weight", "muscle"): 0.2, ("shoulders", "muscle"): 0.3, ("legs", "arms"): 0.5,
                 ("stature", "head"): 0.2, ("shoulders", "chest"): 0.3}


def _ids(topo, *parts):
    codes = [topo.part_names.index(p) for p in parts]
    return np.where(np.isin(topo.vertex_part, codes))[0]


def _tips(cage, J):
    sk = cage.sk
    tips = {}
    for s, base in ((1, 25), (-1, 40)):
        for n, name in enumerate(FINGERS):
            tips[base + 3 * n + 2] = sk.finger_frames[s, name][2] * sk.scale
    for s, foot in ((1, 10), (-1, 11)):
        tips[foot] = J[foot] + np.array([s * 0.012, -0.01, 0.09])
    tips[15] = J[15] + np.array([0, 0.15, 0.0])
    tips[22] = J[22] + np.array([0, -0.07, 0.07])
    return tips


def _jaw_mask(v, topo, cage):
    ids = _ids(topo, "head")
    p = head_local(v[ids] / cage.sk.scale, cage)
    _x, y, z = p.T
    jaw = (y < hd.MOUTH_Y + 0.001 - 0.55 * np.clip(0.085 - z, 0, None)) & (z > -0.035) & (y > -0.135)
    mask = np.zeros(len(v), bool)
    mask[ids[jaw]] = True
    return mask


def _special_vertices(v, topo, cage):
    sk, sc = cage.sk, cage.sk.scale
    out = {}
    head = _ids(topo, "head")
    local = head_local(v[head] / sc, cage)
    mid = np.abs(local[:, 0]) < 0.006
    out["nose"] = head[mid][np.argmax(local[mid, 2])]
    for s, key in ((1, "leye"), (-1, "reye")):
        target = hd.face_point(np.array([s * hd.EYE[0]]), np.array([hd.EYE[1]]))[0]
        out[key] = head[np.argmin(np.linalg.norm(local - target, axis=1))]
    for s, key in ((1, "lear"), (-1, "rear")):
        ear = _ids(topo, "l_ear" if s > 0 else "r_ear")
        out[key] = ear[np.argmin(np.linalg.norm(v[ear] - cage.meta["ear_centre"][s] * sc, axis=1))]
    for s, pre in ((1, "l"), (-1, "r")):
        for name in FINGERS:
            ids = _ids(topo, f"{pre}_{name}")
            d = sk.finger_frames[s, name][0]
            out[pre + name] = ids[np.argmax(v[ids] @ d)]
        foot = _ids(topo, f"{pre}_foot", f"{pre}_leg")
        A = cage.J[7 if s > 0 else 8] * sc
        ang = np.radians(7.0) * s
        fwd = np.array([np.sin(ang), 0, np.cos(ang)])
        lat = np.array([s * np.cos(ang), 0, -s * np.sin(ang)])
        rel = v[foot] - A
        along, side = rel @ fwd, rel @ lat
        low = v[foot, 1] < v[:, 1].min() + 0.03
        big, small = low & (side < -0.005), low & (side > 0.02)
        key = "L" if s > 0 else "R"
        out[key + "BigToe"] = foot[big][np.argmax(along[big] - 0.3 * np.abs(side[big] + 0.025))]
        out[key + "SmallToe"] = foot[small][np.argmax(along[small] - 0.3 * np.abs(side[small] - 0.035))]
        heel = (v[foot, 1] < A[1] - 0.035) & (np.abs(side) < 0.012)
        out[key + "Heel"] = foot[heel][np.argmin(along[heel])]
    return out


def _landmarks(v, faces, topo, cage):
    sc = cage.sk.scale
    pts = cage.sk.ear * sc + hd.face_point(*hd.LANDMARKS_XY.T) * cage.sk.head_scale * sc
    tri_ok = np.isin(faces, _ids(topo, "head")).all(1)
    tris = np.where(tri_ok)[0]
    idx, bary = [], []
    cent = v[faces[tris]].mean(1)
    for p in pts:
        near = tris[np.argsort(np.linalg.norm(cent - p, axis=1))[:12]]
        best = None
        for t in near:
            a, b, c = v[faces[t]]
            m = np.array([b - a, c - a]).T
            uv = np.linalg.lstsq(m, p - a, rcond=None)[0]
            w = np.clip(np.array([1 - uv.sum(), uv[0], uv[1]]), 0, None)
            w /= w.sum()
            dist = np.linalg.norm(w @ np.array([a, b, c]) - p)
            if best is None or dist < best[0]:
                best = (dist, t, w)
        idx.append(best[1])
        bary.append(best[2])
    return np.array(idx, np.int64), np.array(bary)


def _face_contour(v, faces, topo, cage):
    """The 17 jaw-line landmarks for head turns of -39..39 degrees (``smplx``'s ``use_face_contour``
    look-up table): for each turn, the silhouette points of the lower face in 17 directions."""
    head = _ids(topo, "head")
    p = head_local(v[head] / cage.sk.scale, cage)
    normals = vertex_normals(v, faces)[head]
    sel = (p[:, 1] < 0.005) & (p[:, 1] > -0.112) & (p[:, 2] > -0.02) & (normals[:, 1] > -0.92)
    head, p, normals = head[sel], p[sel], normals[sel]
    centre = np.array([0.0, -0.005, 0.0])
    phis = np.radians(np.linspace(188, 352, 17))
    # one incident face per vertex, barycentric weight 1 on that vertex
    first_face = np.full(len(v), -1)
    first_corner = np.zeros(len(v), int)
    for k in (2, 1, 0):
        first_face[faces[:, k]] = np.arange(len(faces))
        first_corner[faces[:, k]] = k
    idx = np.zeros((79, 17), np.int64)
    bary = np.zeros((79, 17, 3))
    for row in range(79):
        a = np.radians(row if row < 40 else 39 - row)
        view = np.array([np.sin(a), 0.0, np.cos(a)])
        ex = np.array([np.cos(a), 0.0, -np.sin(a)])
        px, py = (p - centre) @ ex, p[:, 1] - centre[1]
        ok = normals @ view > -0.05
        ang = np.mod(np.arctan2(py, px), 2 * np.pi)
        radius = np.hypot(px, py)
        for k, phi in enumerate(phis):  # the outermost facing vertex in a narrow wedge around phi
            near = ok & (np.abs(ang - phi) < np.radians(4.0))
            score = np.where(near, radius, -np.inf)
            vid = head[np.argmax(score)]
            idx[row, k] = first_face[vid]
            bary[row, k, first_corner[vid]] = 1.0
    return idx, bary


def _shape_space(v0):
    """Finite differences of the generator in its anatomical parameters (one standard deviation each),
    whitened by the population covariance and rotated to principal axes (largest variance first)."""
    names = SHAPE_PARAMS
    k = len(names)
    D = np.zeros((v0.size, k))
    for i, name in enumerate(names):
        D[:, i] = (surface(params(**{name: 1.0}))[0] - v0).ravel()
    C = np.eye(k)
    for (a, b), r in _CORRELATIONS.items():
        C[names.index(a), names.index(b)] = C[names.index(b), names.index(a)] = r
    L = np.linalg.cholesky(C)
    U, S, _ = np.linalg.svd(D @ L, full_matrices=False)
    dirs = U * S
    for c in range(k):  # sign: a positive coefficient makes the body taller / larger
        if dirs[:, c].reshape(-1, 3)[:, 1].std() and np.dot(dirs[:, c].reshape(-1, 3)[:, 1], v0[:, 1]) < 0:
            dirs[:, c] *= -1
    return dirs.reshape(-1, 3, k)


def build():
    v, topo, cage = surface()
    faces = topo.faces
    sc = cage.sk.scale
    J = cage.J * sc
    tips = _tips(cage, J)
    jaw = _jaw_mask(v, topo, cage)
    weights = rig.skinning_weights(v, faces, topo.vertex_part, topo.part_names, J, tips, jaw)
    # joint regressor support: vertices bound (before diffusion) to the joint or its parent, near the joint
    label = np.argmax(weights, 1)
    support = {}
    for j in range(55):
        near = np.linalg.norm(v - J[j], axis=1)
        fam = {j, PARENTS[j]} | {c for c in range(55) if PARENTS[c] == j}
        if j in (23, 24):
            ok = np.isin(np.arange(len(v)), _ids(topo, "head")) & (near < 0.05)
        elif j == 22:
            ok = np.isin(label, [15, 22]) & (near < 0.075) & (v[:, 1] < J[22][1] + 0.015)
        elif j == 15:
            ok = np.isin(label, [12, 15]) & (np.abs(v[:, 1] - J[15][1]) < 0.02)
        else:
            ok = np.isin(label, list(fam))
            ok &= near < 2.2 * near[ok].min() + 0.01
        support[j] = np.where(ok)[0]
    J_regressor = rig.joint_regressor(v, support, J)
    shapedirs = np.zeros((NUM_VERTICES, 3, 400))
    shapedirs[:, :, :len(SHAPE_PARAMS)] = _shape_space(v)
    head = _ids(topo, "head")
    normals = vertex_normals(v, faces)
    expr = hd.expressions(head_local(v[head] / sc, cage), normals[head]) * cage.sk.head_scale * sc
    shapedirs[head, :, 300:310] = expr
    hml, hcl, hmr, hcr = hand_pca()
    lmk_idx, lmk_bary = _landmarks(v, faces, topo, cage)
    special = _special_vertices(v, topo, cage)
    dyn_idx, dyn_bary = _face_contour(v, faces, topo, cage)
    # permutation: the special vertices go to their SMPL-X ids
    perm = np.full(NUM_VERTICES, -1)
    for key, vid in VERTEX_JOINT_IDS.items():
        perm[vid] = special[key]
    rest = np.setdiff1d(np.arange(NUM_VERTICES), list(special.values()))
    perm[perm < 0] = rest
    inv = np.empty_like(perm)
    inv[perm] = np.arange(NUM_VERTICES)
    parents = PARENTS.copy()
    return {
        "v_template": v[perm],
        "shapedirs": shapedirs[perm],
        "posedirs": np.zeros((NUM_VERTICES, 3, 486)),
        "J_regressor": J_regressor[:, perm],
        "weights": weights[perm],
        "kintree_table": np.stack([np.where(parents < 0, 4294967295, parents), np.arange(55)]).astype(np.int64),
        "f": inv[faces].astype(np.int64),
        "hands_componentsl": hcl, "hands_componentsr": hcr, "hands_meanl": hml, "hands_meanr": hmr,
        "lmk_faces_idx": lmk_idx, "lmk_bary_coords": lmk_bary,
        "dynamic_lmk_faces_idx": dyn_idx, "dynamic_lmk_bary_coords": dyn_bary,
    }, {"joints": J, "part": topo.vertex_part[perm], "part_names": topo.part_names}
