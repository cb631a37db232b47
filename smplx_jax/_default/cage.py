"""A coarse quad cage built by box modelling: grids, extrusions and bridges, each face tagged with a part name."""

import numpy as np


class Cage:
    def __init__(self):
        self.pos = []     # target surface point of each cage vertex
        self.faces = []   # quads, counter-clockwise seen from outside
        self.part = []    # part name of each face

    def vertex(self, p):
        self.pos.append(np.asarray(p, float))
        return len(self.pos) - 1

    def face(self, vs, part):
        self.faces.append(list(vs))
        self.part.append(part)
        return len(self.faces) - 1

    def box(self, n, point, part):
        """Surface of an (nx, ny, nz) grid box; ``point(i, j, k)`` places the vertex. Returns ({(i,j,k): vertex id},
        {(axis, side, (i,j,k) of the cell's lowest corner): face id})."""
        nx, ny, nz = n
        ids = {}
        for i in range(nx + 1):
            for j in range(ny + 1):
                for k in range(nz + 1):
                    if i in (0, nx) or j in (0, ny) or k in (0, nz):
                        ids[i, j, k] = self.vertex(point(i, j, k))
        fids = {}
        # each side: fixed axis a at value s; the two other axes (b, c) with outward orientation
        for axis, sizes in ((0, (ny, nz)), (1, (nz, nx)), (2, (nx, ny))):
            b_ax, c_ax = (axis + 1) % 3, (axis + 2) % 3
            for side in (0, n[axis]):
                for b in range(sizes[0]):
                    for c in range(sizes[1]):
                        quad = []
                        for db, dc in ((0, 0), (1, 0), (1, 1), (0, 1)):
                            key = [0, 0, 0]
                            key[axis], key[b_ax], key[c_ax] = side, b + db, c + dc
                            quad.append(ids[tuple(key)])
                        if side == 0:
                            quad = quad[::-1]
                        cell = [0, 0, 0]
                        cell[axis], cell[b_ax], cell[c_ax] = side, b, c
                        fids[axis, side, tuple(cell)] = self.face(quad, part)
        return ids, fids

    def loop(self, fids):
        """Ordered boundary loop of a disk-shaped set of faces (direction as in the faces)."""
        directed = {}
        for f in fids:
            q = self.faces[f]
            for t in range(len(q)):
                directed[q[t]] = directed.get(q[t], []) + [q[(t + 1) % len(q)]]
        inner = set()
        for f in fids:
            q = self.faces[f]
            for t in range(len(q)):
                a, b = q[t], q[(t + 1) % len(q)]
                if a in directed.get(b, []):
                    inner.add((a, b))
        nxt = {}
        for f in fids:
            q = self.faces[f]
            for t in range(len(q)):
                a, b = q[t], q[(t + 1) % len(q)]
                if (a, b) not in inner:
                    nxt[a] = b
        start = min(nxt)
        out = [start]
        while nxt[out[-1]] != start:
            out.append(nxt[out[-1]])
        assert len(out) == len(nxt), "region boundary is not one loop"
        return out

    def extrude(self, fids, part, place):
        """Extrude faces ``fids``: boundary vertices are duplicated, walls (tagged ``part``) join old and new
        boundary; interior vertices move with the cap. ``place(old_vertex_id)`` gives the new position.
        Returns {old boundary id: new id} (interior ids map to themselves)."""
        ring = self.loop(fids)
        new = {v: self.vertex(place(v)) for v in ring}
        inner = {v for f in fids for v in self.faces[f]} - set(ring)
        for v in inner:
            self.pos[v] = np.asarray(place(v), float)
        for f in fids:
            self.faces[f] = [new.get(v, v) for v in self.faces[f]]
            self.part[f] = part
        for t, a in enumerate(ring):
            b = ring[(t + 1) % len(ring)]
            self.face([a, b, new[b], new[a]], part)
        return new | {v: v for v in inner}

    def bridge(self, fa, fb, part):
        """Delete face sets ``fa`` and ``fb`` (equal boundary lengths) and join their loops by a ring of quads."""
        la, lb = self.loop(fa), self.loop(fb)
        n = len(la)
        assert len(lb) == n
        pa, pb = np.array([self.pos[v] for v in la]), np.array([self.pos[v] for v in lb])
        cost = [sum(np.linalg.norm(pa[i] - pb[(s - i) % n]) for i in range(n)) for s in range(n)]
        s = int(np.argmin(cost))
        for f in sorted(set(fa) | set(fb), reverse=True):
            del self.faces[f], self.part[f]
        for i in range(n):
            self.face([la[i], la[(i + 1) % n], lb[(s - i - 1) % n], lb[(s - i) % n]], part)

    def arrays(self):
        """(positions, quads, parts) without the vertices no face uses any more (bridged caps)."""
        faces = np.array(self.faces, np.int64)
        used = np.unique(faces)
        new_id = np.full(len(self.pos), -1)
        new_id[used] = np.arange(len(used))
        return np.array(self.pos)[used], new_id[faces], list(self.part)
