"""From cage to the final surface: Catmull-Clark twice (fitted so the surface passes through the cage's target
points), triangles, edge splits up to the vertex count, head sculpting, stature."""

import numpy as np

from . import head as hd
from .body import BodyCage
from .skeleton import params as make_params
from .subdiv import catmull_clark, split_longest_edges, triangulate

NUM_VERTICES = 10475
FIT_STEPS = 3


class Topology:
    """Everything that depends only on the cage's connectivity (identical for all shape parameters)."""

    def __init__(self, cage_faces, cage_parts, n_cage, base_pos):
        op1, q1 = catmull_clark(cage_faces, n_cage)
        op2, q2 = catmull_clark(q1, op1.shape[0])
        self.op = op2.compose(op1)
        self.quads = q2
        self.n_fine = self.op.shape[0]
        # the fine surface approaches the cage targets: a few Richardson steps of A P = T (P = T + (T - A P)..)
        # instead of exact interpolation, which rings (overshoots) at sharp features
        A = self.op.dense(np.arange(n_cage))
        step = np.eye(n_cage) - A
        self.fit = np.eye(n_cage)
        for _ in range(FIT_STEPS):
            self.fit = np.eye(n_cage) + step @ self.fit
        self.quad_part = np.repeat(np.array(cage_parts), 16)
        fine = self.op.apply(self.fit @ base_pos)
        tris = triangulate(q2, fine)
        self.tri_part = np.repeat(self.quad_part, 2)
        extra = NUM_VERTICES - self.n_fine
        if extra < 0:
            raise ValueError(f"cage too fine: {self.n_fine} vertices after subdivision")
        self.faces, self.splits = split_longest_edges(tris, fine, extra)
        n_split_tris = len(self.faces) - len(tris)
        # new triangles take the part of the triangle they were cut from
        src = []
        for a, b in self.splits:
            t = np.where((tris == a).any(1) & (tris == b).any(1))[0]
            src += list(t)
        self.tri_part = np.concatenate([self.tri_part, self.tri_part[np.array(src, int)]])[: len(self.faces)]
        assert n_split_tris == len(src)
        parts = sorted(set(cage_parts))
        self.part_names = parts
        code = {p: i for i, p in enumerate(parts)}
        tri_code = np.array([code[p] for p in self.tri_part])
        self.vertex_part = np.full(NUM_VERTICES, -1)
        # a vertex belongs to the part of (the first of) its triangles, ears and fingers winning over the rest
        rank = np.array([0 if p in ("torso", "head", "neck") else 1 for p in parts])
        order = np.argsort(rank[tri_code], kind="stable")
        for t in order:
            self.vertex_part[self.faces[t]] = tri_code[t]


_TOPOLOGY = {}


def surface(p=None):
    """(vertices (10475,3), faces, topology, cage) for shape parameters ``p``."""
    cage = BodyCage(make_params() if p is None else p)
    pos, faces, parts = cage.c.arrays()
    key = (len(pos), faces.tobytes())
    if key not in _TOPOLOGY:
        base = BodyCage(make_params()).c.arrays()[0]
        _TOPOLOGY[key] = Topology(faces, parts, len(pos), base)
    topo = _TOPOLOGY[key]
    fine = topo.op.apply(topo.fit @ pos)
    fine = np.concatenate([fine, fine[topo.splits].mean(1)])
    fine = sculpt_torso(fine, topo, cage)
    fine = sculpt_head(fine, topo, cage)
    fine = relax_neck(fine, topo, cage)
    return fine * cage.sk.scale, topo, cage


def head_local(v, cage):
    return (v - cage.sk.ear) / cage.sk.head_scale


def sculpt_head(v, topo, cage):
    """Project head vertices onto the featured head surface (ears and the lower neck excluded)."""
    names = topo.part_names
    ids = np.where(np.isin(topo.vertex_part, [names.index("head"), names.index("neck")]))[0]
    local = head_local(v[ids], cage)
    rel = local - hd.RAY_ORIGIN
    target = hd.cast(rel, near=np.linalg.norm(rel, axis=1), iterations=11)
    rel = local - hd.RAY_ORIGIN
    ray_z = rel[:, 2] / np.linalg.norm(rel, axis=1)
    w = hd.smoothstep(0.15, 0.45, ray_z)  # the face; the skull and jaw underside keep the smooth base shape
    w = w * hd.smoothstep(0.028, 0.040, np.linalg.norm((np.abs(local) - hd.EAR) * (1, 0.8, 1), axis=1))
    out = v.copy()
    out[ids] = v[ids] + (w[:, None] * (target - local)) * cage.sk.head_scale
    return out


def _bump(x, y, cx, cy, sx, sy):
    return np.exp(-((x - cx) / sx) ** 2 - ((y - cy) / sy) ** 2)


def sculpt_torso(v, topo, cage):
    """Chest, shoulder blades, belly, navel, buttocks and spine: smooth bumps along the horizontal normal."""
    sk = cage.sk
    ids = np.where(np.abs(v[:, 0]) < 0.3)[0]
    x, y, z = v[ids].T
    yt = sk.HIP_Y + (y - sk.HIP_Y) / sk.torso_len  # template heights
    front, back = z > 0, z < 0
    ax = np.abs(x)
    g = sk.girth
    d = np.zeros(len(ids))
    d += front * 0.013 * sk.chest * _bump(ax, yt, 0.080, -0.070, 0.050, 0.045)           # chest
    d += front * 0.004 * _bump(ax, yt, 0.070, 0.085, 0.045, 0.012)                       # collar bones
    d += front * (0.010 + 0.006 * sk.belly) * _bump(x, yt, 0.0, -0.300, 0.085, 0.075)     # belly
    d -= front * 0.005 * _bump(x, yt, 0.0, -0.275, 0.008, 0.008)                         # navel
    d += back * 0.024 * g * _bump(ax, yt, 0.072, -0.455, 0.060, 0.065)                   # buttocks
    d += back * 0.008 * _bump(ax, yt, 0.080, -0.010, 0.040, 0.060)                       # shoulder blades
    d -= back * 0.005 * np.exp(-(x / 0.018) ** 2) * _bump(0, yt, 0, -0.15, 1, 0.17)          # spine groove
    d -= 0.010 * _bump(ax, yt, 0.140, -0.200, 0.030, 0.080) * (np.abs(z) < 0.06)          # waist
    radial = np.stack([x, np.zeros_like(x), z], 1)
    radial /= np.linalg.norm(radial, axis=1, keepdims=True) + 1e-9
    out = v.copy()
    out[ids] += d[:, None] * radial
    return out


def relax_neck(v, topo, cage, iterations=10):
    """Laplacian smoothing in the band where the head's underside meets the neck (removes small folds)."""
    if not hasattr(topo, "edges"):
        from .subdiv import edges_of
        topo.edges = edges_of(topo.faces)[0]
        topo.degree = np.bincount(topo.edges.ravel(), minlength=len(v)).astype(float)
    e, deg = topo.edges, topo.degree
    local = head_local(v, cage)
    y, z = local[:, 1], local[:, 2]
    names = topo.part_names
    band = np.isin(topo.vertex_part, [names.index("head"), names.index("neck")])
    w = 0.5 * band * hd.smoothstep(-0.160, -0.130, y) * (1 - hd.smoothstep(-0.090, -0.070, y))
    w = w * (1 - hd.smoothstep(0.045, 0.070, z))  # not the chin
    out = v.copy()
    for _ in range(iterations):
        acc = np.stack([np.bincount(e[:, 0], out[e[:, 1], c], len(v)) + np.bincount(e[:, 1], out[e[:, 0], c], len(v))
                        for c in range(3)], 1)
        out = out + w[:, None] * (acc / deg[:, None] - out)
    return out
