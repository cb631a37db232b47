"""The body cage: a torso box with legs, arms, hands, fingers, feet, neck, head and ears extruded from it.
Every cage vertex is placed on the intended body surface; the subdivided surface is later fitted through them."""

import numpy as np

from . import head as hd
from .cage import Cage
from .skeleton import LONG_FINGERS, Skeleton

X, Y, Z = np.eye(3)
HAND_FINGERS = {0: "pinky", 1: "ring", 2: "middle", 3: "index"}  # cap face k of the hand -> finger
HEAD_N = (6, 7, 3)
_HEAD_CAST = {}


def _ring_angle(u, w):
    """Angle (deg) of a point on the boundary of the unit square [-1,1]^2, evenly spaced along it."""
    if abs(w) == 1 and abs(u) <= 1:
        return 90.0 - 45.0 * u if w > 0 else -90.0 + 45.0 * u
    return 45.0 * w if u > 0 else 180.0 - 45.0 * w


def _se(c, e):
    return np.sign(c) * np.abs(c) ** (2.0 / e)


def _oval(theta, pos_a, neg_a, pos_b, neg_b, e=2.0):
    c, s = np.cos(theta), np.sin(theta)
    return _se(c, e) * (pos_a if c >= 0 else neg_a), _se(s, e) * (pos_b if s >= 0 else neg_b)


class BodyCage:
    """Builds the cage for one set of shape parameters; ``meta`` keeps what rigging needs."""

    def __init__(self, p):
        self.sk = sk = Skeleton(p)
        self.J = sk.joints
        self.c = Cage()
        self.meta = {}
        self._torso()
        for s in (1, -1):
            self._arm(s)
            self._leg(s)
        self._head()

    def _extrude(self, faces, part, place, slot):
        """Extrude ``faces`` of the cage into ``part``, new vertices placed by ``place``; each new vertex inherits
        the ``slot`` of the vertex it was extruded from. Returns old -> new vertex ids."""
        mapping = self.c.extrude(faces, part, place)
        for old, new in list(mapping.items()):
            if old in slot:
                slot[new] = slot[old]
        return mapping

    # ------------------------------------------------------------------ torso
    def _levels(self):
        sk = self.sk
        g, hw, sw, ch, b = sk.girth, sk.hip_w, sk.shoulder_w, sk.chest, sk.belly
        t = sk.ty
        return [
            {"y": t(-0.497), "a": 0.158 * hw * g, "zf": 0.070 * g + 0.003 * b, "zb": -0.092 * g, "e": 2.3},
            {"y": t(-0.392), "a": 0.165 * hw * g, "zf": 0.086 * g + 0.006 * b, "zb": -0.116 * g, "e": 2.3},
            {"y": t(-0.212), "a": 0.132 * g ** 1.2, "zf": 0.090 * g + 0.010 * b, "zb": -0.082 * g, "e": 2.2},
            {"y": t(-0.004), "a": 0.156 * sw * g, "zf": 0.106 * ch * g, "zb": -0.098 * g, "e": 2.4},
            {"y": t(0.086), "a": 0.180 * sw + 0.15 * (g - 1), "zf": 0.058, "zb": -0.078, "e": 2.0},
        ]

    def _torso(self):
        L = self._levels()
        sk = self.sk

        def point(i, j, k):
            u, w = (i - 2) / 2, (k - 2) / 2
            on_rim = abs(u) == 1 or abs(w) == 1
            if on_rim:
                lv = L[j]
                th = np.radians(_ring_angle(u, w))
                x, z = _oval(th, lv["a"], lv["a"], lv["zf"], -lv["zb"], lv["e"])
                y = lv["y"]
                if j == 4:  # shoulder line: lower laterally, rising to the neck
                    y += 0.012 * (1 - abs(np.cos(th)))
                if j == 3 and abs(u) == 1:  # armpits
                    x *= 0.97
                return (x, y, z)
            if j == 4:  # neck base ring on the top face
                if u == 0 and w == 0:
                    return (0, sk.ty(0.130), -0.028)
                th = np.arctan2(w, u)
                r = 0.057 * sk.girth ** 0.5
                return (r * np.cos(th), sk.ty(0.110) - 0.010 * np.sin(th), -0.028 + 0.054 * np.sin(th))
            # bottom face interior: crotch line (u = 0), groin (w > 0), gluteal fold (w < 0)
            if u == 0:
                return (0, sk.ty(-0.532), 0.048 * w * 2)
            x = np.sign(u) * 0.080 * sk.hip_w
            if w > 0:
                return (x, sk.ty(-0.525), 0.062 * sk.girth)
            if w < 0:
                return (x, sk.ty(-0.545), -0.090 * sk.girth)
            return (x, sk.ty(-0.56), 0.0)  # leg cap centre (moved by the leg extrusions)

        ids, fids = self.c.box((4, 4, 4), point, "torso")
        self.torso_ids, self.torso_fids = ids, fids
        # arm openings: the top row of each side; leg openings: two 2x2 patches of the bottom; neck: top centre
        self.arm_patch = {s: [fids[0, 4 if s > 0 else 0, (4 if s > 0 else 0, 3, k)] for k in range(4)]
                          for s in (1, -1)}
        self.leg_patch = {s: [fids[1, 0, (i, 0, k)] for i in ((2, 3) if s > 0 else (0, 1)) for k in (1, 2)]
                          for s in (1, -1)}
        self.neck_patch = [fids[1, 4, (i, 4, k)] for i in (1, 2) for k in (1, 2)]

    # ------------------------------------------------------------------ arms and hands
    def _arm(self, s):
        """The arm from its torso opening to the wrist, then the hand."""
        J, sk = self.J, self.sk
        sh, el, wr = (16, 18, 20) if s > 0 else (17, 19, 21)
        S, E, W = J[sh], J[el], J[wr]
        g, m = sk.girth, sk.muscle
        ti = 4 if s > 0 else 0
        slot = {}  # vertex -> (row "top"/"bot", column 0-4) around the arm
        for k in range(5):
            slot[self.torso_ids[ti, 4, k]] = ("top", k)
            slot[self.torso_ids[ti, 3, k]] = ("bot", k)
        patch = self.arm_patch[s]
        part = "l_arm" if s > 0 else "r_arm"

        def oval_ring(center, ry, rz):
            def place(v):
                row, k = slot[v]
                phi = np.radians(-72 + 36 * k if row == "top" else 108 + 36 * (4 - k))
                return center + ry * np.cos(phi) * Y + rz * np.sin(phi) * Z
            return place

        self._extrude(patch, part, oval_ring(S + (s * 0.032, 0.010, 0.006), 0.050 * g * m, 0.053 * g * m), slot)
        self._extrude(patch, part, oval_ring(E + (0, 0.002, -0.002), 0.034 * g, 0.037 * g), slot)
        self._extrude(patch, part, oval_ring(E + 0.28 * (W - E), 0.035 * g * m, 0.041 * g * m), slot)
        wrist_ring = self._extrude(patch, part, oval_ring(W + (-s * 0.006, 0.0, 0.003), 0.0185 * g, 0.0285 * g),
                                   slot)
        self._hand(s, patch, slot, wrist_ring)

    def _hand(self, s, patch, slot, wrist_ring):
        """Palm rings from the wrist's ``patch``, a finger from each of its four cap faces, the thumb from the
        palm's front wall."""
        c, sk = self.c, self.sk
        W, g, al = self.J[20 if s > 0 else 21], sk.girth, sk.arm_len
        hand = "l_hand" if s > 0 else "r_hand"

        def hand_ring(dxs, zs, thick):
            def place(v):
                row, k = slot[v]
                yy = 0.5 * thick * (0.45 if k in (0, 4) else 1.0) * (1 if row == "top" else -1)
                if row == "top" and k == 2:
                    yy += 0.002
                return W + (s * dxs[k] * al, yy - 0.003, zs[k] * al)
            return place

        mid = self._extrude(patch, hand, hand_ring([0.047] * 5, 0.0025 + 0.0415 * g * np.linspace(-1, 1, 5), 0.027 * g),
                            slot)
        self._extrude(patch, hand, hand_ring([0.088, 0.094, 0.098, 0.097, 0.093],
                                             [-0.0405, -0.0205, -0.0025, 0.0165, 0.0365], 0.021 * g), slot)
        # fingers from the four cap faces
        for f in patch:
            ks = sorted({slot[v][1] for v in c.faces[f]})
            name = HAND_FINGERS[ks[0]]
            self._finger(s, f, slot, name)
        # thumb from the front wall between the wrist ring and the mid-palm ring
        ring5 = {slot[v]: v for v in wrist_ring.values() if v in slot}
        ring6 = {slot[v]: v for v in mid.values() if v in slot}
        want = {ring5["top", 4], ring5["bot", 4], ring6["top", 4], ring6["bot", 4]}
        face = next(i for i, q in enumerate(c.faces) if set(q) == want)
        tslot = {ring5["top", 4]: (1, -1), ring5["bot", 4]: (-1, -1), ring6["top", 4]: (1, 1),
                 ring6["bot", 4]: (-1, 1)}
        self._thumb(s, face, tslot)

    def _finger(self, s, f, slot, name):
        c, sk = self.c, self.sk
        base = 25 if s > 0 else 40
        n = ["index", "middle", "pinky", "ring", "thumb"].index(name)
        _j1, j2, j3 = (self.J[base + 3 * n + i] for i in range(3))
        d, up, tip, _lengths = sk.finger_frames[s, name]
        side = np.cross(d, up)
        side = side if side[2] > 0 else -side
        _, _, _, _, hw, ht = LONG_FINGERS[name]
        kmin = min(slot[v][1] for v in c.faces[f])
        fslot = {v: (1 if slot[v][0] == "top" else -1, 1 if slot[v][1] > kmin else -1) for v in c.faces[f]}
        part = ("l_" if s > 0 else "r_") + name

        def ring(center, a, b):
            def place(v):
                su, sd = fslot[v]
                return center + su * b * up + sd * a * side
            return place

        for center, a, b in ((j2 + 0.0012 * up, 0.95 * hw, 0.93 * ht), (j3 + 0.0010 * up, 0.84 * hw, 0.80 * ht),
                             (tip - 0.0042 * d + 0.0008 * up, 0.58 * hw, 0.52 * ht)):
            self._extrude([f], part, ring(center, a, b), fslot)

    def _thumb(self, s, f, tslot):
        c, sk = self.c, self.sk
        base = 25 if s > 0 else 40
        t1, t2, t3 = (self.J[base + 12 + i] for i in range(3))
        d, up, tip, _lengths = sk.finger_frames[s, "thumb"]
        distal = s * X - np.dot(s * X, d) * d
        distal -= np.dot(distal, up) * up
        distal /= np.linalg.norm(distal)
        part = "l_thumb" if s > 0 else "r_thumb"

        def ring(center, a, b):
            def place(v):
                su, sd = tslot[v]
                return center + su * b * up + sd * a * distal
            return place

        root = np.mean([c.pos[v] for v in c.faces[f]], 0)
        for center, a, b in ((0.5 * (root + t1 + 0.026 * d) + 0.006 * Z, 0.0150, 0.0118),
                             (t2 + 0.0008 * up, 0.0105, 0.0095), (t3 + 0.0008 * up, 0.0094, 0.0084),
                             (tip - 0.0045 * d + 0.0008 * up, 0.0060, 0.0052)):
            self._extrude([f], part, ring(center, a, b), tslot)

    # ------------------------------------------------------------------ legs and feet
    def _leg(self, s):
        """The leg from its torso opening to the heel, then the foot."""
        c, J, sk = self.c, self.J, self.sk
        hip, knee, ankle = (1, 4, 7) if s > 0 else (2, 5, 8)
        H, K, A = J[hip], J[knee], J[ankle]
        g, m = sk.girth, sk.muscle
        slot = {}  # rim vertex -> its angle around the leg (the cap centre has none)
        ic = 3 if s > 0 else 1
        for f in self.leg_patch[s]:
            for v in c.faces[f]:
                key = next(key for key, vid in self.torso_ids.items() if vid == v)
                du, dw = (key[0] - ic) / 2, (key[2] - 2) / 2
                if du or dw:
                    slot[v] = np.arctan2(dw, du * s)
        part = "l_leg" if s > 0 else "r_leg"
        patch = self.leg_patch[s]

        def ring(center, lat, med, front, back, ydrop=None):
            def place(v):
                if v not in slot:  # cap centre
                    return center + (0, -0.030 if ydrop is None else ydrop, 0)
                psi = slot[v]
                a, b = _oval(psi, lat, med, front, back)
                p = center + a * s * X + b * Z
                if ydrop is not None:
                    p = p + (0, -0.016 * max(0.0, np.sin(psi)), 0)
                return p
            return place

        gm = g * m
        ly = sk.ly
        for center, lat, med, front, back in (
            (np.array([H[0] + s * 0.018, ly(-0.600), 0.002]), 0.072 * gm, 0.070 * gm, 0.072 * gm, 0.076 * gm),
            (H + 0.72 * (K - H) + (s * 0.008, 0, 0.010), 0.062 * gm, 0.060 * gm, 0.062 * gm, 0.058 * gm),
            (K + (0, 0, 0.004), 0.047 * g, 0.050 * g, 0.052 * g, 0.043 * g),
            (np.array([K[0] - s * 0.004, ly(-0.955), -0.016]), 0.045 * gm, 0.049 * gm, 0.037 * g, 0.056 * gm),
        ):
            self._extrude(patch, part, ring(center, lat, med, front, back), slot)
        r5 = self._extrude(patch, part, ring(np.array([A[0], ly(-1.163), A[2] + 0.004]), 0.029, 0.031, 0.030, 0.034),
                           slot)
        r6 = self._extrude(patch, part, ring(np.array([A[0] + s * 0.002, ly(-1.268), A[2] + 0.010]), 0.035, 0.035,
                                             0.050, 0.057, ydrop=-0.034), slot)
        self._foot(s, slot, r5, r6)

    def _foot(self, s, slot, r5, r6):
        """The foot from the two front wall faces between the ankle ring ``r5`` and the heel ring ``r6``."""
        c, A = self.c, self.J[7 if s > 0 else 8]
        s5 = {round(np.degrees(slot[v])): v for v in r5.values() if v in slot}
        s6 = {round(np.degrees(slot[v])): v for v in r6.values() if v in slot}
        fslot = {}
        for col, ang in (("lat", 45), ("mid", 90), ("med", 135)):
            fslot[s5[ang]] = ("top", col)
            fslot[s6[ang]] = ("bot", col)
        faces = [i for i, q in enumerate(c.faces) if set(q) <= set(fslot) and len(set(q)) == 4]
        assert len(faces) == 2
        foot = "l_foot" if s > 0 else "r_foot"
        toe_out = np.radians(7.0) * s
        R = np.array([[np.cos(toe_out), 0, np.sin(toe_out)], [0, 1, 0], [-np.sin(toe_out), 0, np.cos(toe_out)]])
        y0 = self.sk.ly(-1.300)

        def foot_ring(dz, tops, bots, xs):
            def place(v):
                row, col = fslot[v]
                i = ("lat", "mid", "med").index(col)
                local = np.array([s * xs[i], (tops if row == "top" else bots)[i], dz[i]])
                return np.array([A[0], y0, A[2]]) + R @ local
            return place

        for dz, tops, bots, xs in (
            ((0.120, 0.120, 0.120), (0.052, 0.072, 0.068), (0.002, 0.005, 0.014), (0.050, 0.007, -0.038)),
            ((0.196, 0.210, 0.216), (0.016, 0.026, 0.030), (0.0, 0.0, 0.0), (0.040, 0.006, -0.034)),
        ):
            self._extrude(faces, foot, foot_ring(dz, tops, bots, xs), fslot)

    # ------------------------------------------------------------------ neck and head
    def _head(self):
        c, sk = self.c, self.sk
        hs = sk.head_scale
        origin = sk.ear  # head-local origin (absolute)
        neck_top_y = -0.096

        # neck: one ring, then bridged to the head's bottom opening
        def neck_place(v):
            key = next(key for key, vid in self.torso_ids.items() if vid == v)
            u, w = (key[0] - 2) / 2, (key[2] - 2) / 2
            th = np.arctan2(w, u)
            r = 0.050 * sk.girth ** 0.5
            y = 0.5 * (sk.ty(0.110) + origin[1] + neck_top_y * hs) - 0.011 * np.sin(th)
            return (r * np.cos(th), y, -0.028 + 0.050 * np.sin(th))

        c.extrude(self.neck_patch, "neck", neck_place)
        nx, ny, nz = HEAD_N
        box = np.array([0.080, 0.105, 0.075])

        keys = [(i, j, k) for i in range(nx + 1) for j in range(ny + 1) for k in range(nz + 1)
                if i in (0, nx) or j in (0, ny) or k in (0, nz)]
        if keys[0] not in _HEAD_CAST:  # head-local, the same for every shape
            u, v, w = (np.array(t, float) for t in zip(*keys))
            u, v, w = 2 * u / nx - 1, 2 * v / ny - 1, 2 * w / nz - 1
            q = np.stack([np.tan(u * 0.9) / np.tan(0.9), v, w], -1) * box
            _HEAD_CAST.update(zip(keys, hd.cast(q, with_features=False, iterations=24)))
        cast = {key: origin + _HEAD_CAST[key] * hs for key in keys}

        def point(i, j, k):
            if j == 0 and 2 <= i <= 4 and k <= 2:  # neck opening, higher at the nape than at the throat
                if i == 3 and k == 1:
                    return origin + (0, (neck_top_y - 0.01) * hs, -0.026)
                th = np.arctan2((k - 1), (i - 3))
                y = (neck_top_y - 0.012 * np.sin(th)) * hs
                return origin + np.array([0.047 * np.cos(th), y, (-0.028 + 0.047 * np.sin(th))])
            return cast[i, j, k]

        ids, fids = c.box(HEAD_N, point, "head")
        self.head_ids = ids
        bottom = [fids[1, 0, (i, 0, k)] for i in (2, 3) for k in (0, 1)]
        # ears: two faces of the back column of each side, around the ear canal
        for s, side in ((1, nx), (-1, 0)):
            self._ear(s, [fids[0, side, (side, 3, 0)], fids[0, side, (side, 4, 0)]], ids, origin, hs)
        c.bridge(self.neck_patch, bottom, "neck")

    def _ear(self, s, fs, ids, origin, hs):
        c = self.c
        key_of = {vid: key for key, vid in ids.items()}
        slot = {v: (key_of[v][1] - 3, key_of[v][2]) for f in fs for v in c.faces[f]}  # (0..2 up, 0 back/1 front)
        part = "l_ear" if s > 0 else "r_ear"
        base = origin + np.array([s * 0.070, 0.0, -0.006]) * hs
        rim = {(2, 0): (0.014, 0.030, -0.024), (2, 1): (0.009, 0.028, -0.004), (1, 1): (0.008, 0.004, 0.002),
               (0, 1): (0.006, -0.026, -0.002), (0, 0): (0.009, -0.022, -0.015), (1, 0): (0.016, 0.004, -0.028)}

        def place(v):
            dx, dy, dz = rim[slot[v]]
            return base + np.array([s * dx, dy, dz]) * hs

        c.extrude(fs, part, place)
        self.meta.setdefault("ear_centre", {})[s] = base + np.array([s * 0.013, 0.004, -0.012]) * hs
