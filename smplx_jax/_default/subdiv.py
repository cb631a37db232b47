"""Linear mesh operators: Catmull-Clark subdivision as a sparse matrix, triangulation, edge splitting."""

import numpy as np


class Sparse:
    """A small COO sparse matrix (numpy only): ``apply`` multiplies, ``compose`` chains two operators."""

    def __init__(self, rows, cols, vals, shape):
        key = np.asarray(rows, np.int64) * shape[1] + np.asarray(cols, np.int64)
        uniq, inv = np.unique(key, return_inverse=True)
        self.vals = np.bincount(inv, weights=np.asarray(vals, np.float64), minlength=len(uniq))
        self.rows, self.cols = uniq // shape[1], uniq % shape[1]
        self.shape = shape

    def apply(self, x):
        x = np.asarray(x, np.float64)
        flat = x.reshape(x.shape[0], -1)
        out = np.zeros((self.shape[0], flat.shape[1]))
        for c in range(flat.shape[1]):
            out[:, c] = np.bincount(self.rows, weights=self.vals * flat[self.cols, c], minlength=self.shape[0])
        return out.reshape((self.shape[0],) + x.shape[1:])

    def compose(self, inner):
        """``self @ inner``."""
        order = np.argsort(inner.rows, kind="stable")
        irows, icols, ivals = inner.rows[order], inner.cols[order], inner.vals[order]
        start = np.searchsorted(irows, np.arange(inner.shape[0] + 1))
        count = start[self.cols + 1] - start[self.cols]
        rep = np.repeat(np.arange(len(self.rows)), count)
        offs = np.arange(len(rep)) - np.repeat(np.cumsum(count) - count, count)
        src = start[self.cols][rep] + offs
        return Sparse(self.rows[rep], icols[src], self.vals[rep] * ivals[src], (self.shape[0], inner.shape[1]))

    def dense(self, row_ids=None):
        out = np.zeros(self.shape)
        out[self.rows, self.cols] = self.vals
        return out if row_ids is None else out[row_ids]


def edges_of(faces):
    """Unique undirected edges (E,2) and, per face corner, the edge from that corner to the next."""
    k = faces.shape[1]
    a = faces.ravel()
    b = np.roll(faces, -1, axis=1).ravel()
    key = np.minimum(a, b) * (faces.max() + 1) + np.maximum(a, b)
    uniq, inv = np.unique(key, return_inverse=True)
    n = faces.max() + 1
    return np.stack([uniq // n, uniq % n], 1), inv.reshape(-1, k)


def catmull_clark(quads, nv):
    """One Catmull-Clark step of a closed quad mesh. New vertices: old vertex points, edge points, face points.
    Returns (operator, new quads); child faces 4f..4f+3 come from face f (corner order kept)."""
    nf = len(quads)
    edges, fe = edges_of(quads)
    ne = len(edges)
    rows, cols, vals = [], [], []

    def add(r, c, v):
        rows.append(r)
        cols.append(c)
        vals.append(v)

    fp = nv + ne + np.arange(nf)
    # face points
    add(np.repeat(fp, 4), quads.ravel(), np.full(4 * nf, 0.25))
    # edge points: 1/4 each endpoint + 1/4 each adjacent face point (1/16 per face corner)
    add(nv + np.repeat(np.arange(ne), 2), edges.ravel(), np.full(2 * ne, 0.25))
    ef = fe.ravel()  # each face corner names one edge adjacent to that face
    face_of = np.repeat(np.arange(nf), 4)
    add(np.repeat(nv + ef, 4), quads[face_of].ravel(), np.full(16 * nf, 1 / 16))
    # vertex points: (Favg + 2 Ravg + (n-3) P) / n
    val = np.bincount(edges.ravel(), minlength=nv).astype(float)
    vf = quads.ravel()  # vertex of each corner, its face's 4 vertices at 1/(4 n^2)
    add(np.repeat(vf, 4), quads[face_of].ravel(), np.repeat(1.0 / (4 * val[vf] ** 2), 4))
    for s, o in ((0, 1), (1, 0)):  # edge midpoints: each edge (v, w) adds (v + w) / (n^2) to v
        v, w = edges[:, s], edges[:, o]
        add(v, v, 1.0 / val[v] ** 2)
        add(v, w, 1.0 / val[v] ** 2)
    add(np.arange(nv), np.arange(nv), (val - 3) / val)
    op = Sparse(np.concatenate(rows), np.concatenate(cols), np.concatenate(vals), (nv + ne + nf, nv))
    ep = nv + fe
    new = np.stack([quads, ep, np.repeat(fp[:, None], 4, 1), np.roll(ep, 1, axis=1)], axis=2)  # (F,4 corners,4)
    return op, new.reshape(-1, 4)


def triangulate(quads, pos=None):
    """Two triangles per quad, split along the shorter diagonal when positions are given."""
    if pos is None:
        short02 = np.ones(len(quads), bool)
    else:
        d02 = np.linalg.norm(pos[quads[:, 0]] - pos[quads[:, 2]], axis=1)
        d13 = np.linalg.norm(pos[quads[:, 1]] - pos[quads[:, 3]], axis=1)
        short02 = d02 <= d13
    a = np.where(short02[:, None], quads[:, [0, 1, 2]], quads[:, [0, 1, 3]])
    b = np.where(short02[:, None], quads[:, [0, 2, 3]], quads[:, [1, 2, 3]])
    return np.stack([a, b], 1).reshape(-1, 3)


def split_longest_edges(tris, pos, count):
    """Split ``count`` longest edges (no two in one triangle) at their midpoints.
    Returns (new triangles, (count, 2) endpoint pairs of the new vertices, appended after the old ones)."""
    nv = len(pos)
    edges, te = edges_of(tris)
    length = np.linalg.norm(pos[edges[:, 0]] - pos[edges[:, 1]], axis=1)
    edge_tris = [[] for _ in range(len(edges))]
    for t, row in enumerate(te):
        for e in row:
            edge_tris[e].append(t)
    used = np.zeros(len(tris), bool)
    chosen = []
    for e in np.argsort(-length, kind="stable"):
        ts = edge_tris[e]
        if not used[ts].any():
            used[ts] = True
            chosen.append(e)
            if len(chosen) == count:
                break
    tris = tris.copy()
    extra = []
    for n, e in enumerate(chosen):
        a, b = edges[e]
        m = nv + n
        for t in edge_tris[e]:
            tri = tris[t]
            k = next(i for i in range(3) if {tri[i], tri[(i + 1) % 3]} == {a, b})
            p, q, r = tri[k], tri[(k + 1) % 3], tri[(k + 2) % 3]
            tris[t] = (p, m, r)
            extra.append((m, q, r))
    return np.concatenate([tris, np.array(extra, np.int64).reshape(-1, 3)]), edges[chosen]
