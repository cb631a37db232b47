"""Anatomical parameters and the 55 joint positions of the default body (SMPL-X frame: y up, +z forward,
the body's left at +x, metres)."""

from functools import lru_cache

import numpy as np

from .head import EYE, face_point

PARENTS = np.array([-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15, 20, 25, 26,
                    20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38, 21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50,
                    21, 52, 53])

# Anatomical shape parameters, each 0 for the template, 1 = one population standard deviation.
SHAPE_PARAMS = ("stature", "weight", "shoulders", "hips", "legs", "arms", "torso", "head", "chest", "belly",
                "muscle")

FINGERS = ("index", "middle", "pinky", "ring", "thumb")  # SMPL-X order
# Long fingers: (z offset from the hand axis, MCP x offset from the wrist, spread angle (deg, +z positive),
#   phalanx lengths, half width, half thickness).
LONG_FINGERS = {
    "index": (0.0255, 0.086, 5.0, (0.041, 0.024, 0.022), 0.0090, 0.0086),
    "middle": (0.0065, 0.089, 0.0, (0.045, 0.028, 0.023), 0.0093, 0.0088),
    "ring": (-0.0120, 0.085, -5.0, (0.042, 0.027, 0.022), 0.0086, 0.0082),
    "pinky": (-0.0290, 0.078, -11.0, (0.033, 0.020, 0.020), 0.0074, 0.0070),
}
THUMB_LENGTHS = (0.044, 0.032, 0.028)


@lru_cache(maxsize=1)
def _eye_surface_z():
    return float(face_point(np.array([EYE[0]]), np.array([EYE[1]]))[0, 2])


def params(**kw):
    p = dict.fromkeys(SHAPE_PARAMS, 0.0)
    p.update(kw)
    return p


def thumb_frame(side):
    """Unit direction of the thumb (flat hand) and a dorsal unit vector orthogonal to it."""
    d = np.array([side * 1.0, -0.30, 1.05])
    d /= np.linalg.norm(d)
    up = np.array([0.0, 1.0, 0.0]) - d[1] * d
    return d, up / np.linalg.norm(up)


def finger_dir(side, spread_deg):
    a = np.radians(spread_deg)
    return np.array([side * np.cos(a), -0.02, np.sin(a)]) / np.hypot(1.0, 0.02)


class Skeleton:
    """Joint positions and the key body measurements derived from the shape parameters."""

    def __init__(self, p):
        self.p = p
        st = 1.0 + 0.035 * p["stature"]
        self.scale = st
        self.girth = 1.0 + 0.05 * p["weight"]
        self.leg_len = 1.0 + 0.035 * p["legs"]
        self.arm_len = 1.0 + 0.035 * p["arms"]
        self.torso_len = 1.0 + 0.03 * p["torso"]
        self.head_scale = 1.0 + 0.025 * p["head"]
        self.shoulder_w = 1.0 + 0.045 * p["shoulders"]
        self.hip_w = 1.0 + 0.045 * p["hips"]
        self.chest = 1.0 + 0.06 * p["chest"]
        self.belly = p["belly"] + 0.5 * p["weight"]
        self.muscle = 1.0 + 0.05 * p["muscle"]
        self.joints = self._joints()

    # y of the hip joints; the torso stretches above, the legs below
    HIP_Y = -0.445

    def ty(self, y):
        """Vertical position of a torso height ``y`` (template metres) under torso length."""
        return self.HIP_Y + (y - self.HIP_Y) * self.torso_len

    def ly(self, y):
        """Vertical position of a leg height ``y`` (template metres) under leg length."""
        return self.HIP_Y + (y - self.HIP_Y) * self.leg_len

    def _joints(self):
        J = np.zeros((55, 3))
        t, ly, hw, sw = self.ty, self.ly, self.hip_w, self.shoulder_w
        J[0] = (0, t(-0.352), 0.012)
        J[3] = (0, t(-0.235), -0.012)
        J[6] = (0, t(-0.108), -0.008)
        J[9] = (0, t(-0.052), -0.005)
        J[12] = (0, t(0.137), -0.030)
        J[15] = (0, t(0.137) + 0.088 * self.head_scale, -0.008)
        for s, (hip, knee, ankle, foot, collar, sh, el, wr) in ((1, (1, 4, 7, 10, 13, 16, 18, 20)),
                                                                 (-1, (2, 5, 8, 11, 14, 17, 19, 21))):
            J[hip] = (s * (0.066 * hw + 0.06 * (self.girth - 1)), self.HIP_Y, -0.004)
            J[knee] = (J[hip][0] + s * 0.036, ly(-0.825), -0.004)
            J[ankle] = (J[hip][0] + s * 0.018, ly(-1.212), -0.046)
            J[foot] = (J[hip][0] + s * 0.046, ly(-1.212) - 0.068, 0.080)
            J[collar] = (s * 0.072, t(0.068), -0.022)
            J[sh] = (s * (0.172 * sw + 0.15 * (self.girth - 1)), t(0.046), -0.026)
            ua, fa = 0.262 * self.arm_len, 0.243 * self.arm_len
            J[el] = J[sh] + (s * ua, -0.008, -0.008)
            J[wr] = J[el] + (s * fa, -0.005, 0.004)
        head = J[15]
        self.ear = np.array([0.0, head[1] + 0.032 * self.head_scale, head[2] - 0.004])
        J[22] = self.ear + np.array([0, -0.018, 0.022]) * self.head_scale
        eye_z = _eye_surface_z() - 0.013  # eyeball centre 13 mm behind the closed lid
        for s, eye in ((1, 23), (-1, 24)):
            J[eye] = self.ear + np.array([s * EYE[0], EYE[1], eye_z]) * self.head_scale
        self.finger_frames = {}
        for s, wr, base in ((1, 20, 25), (-1, 21, 40)):
            W = J[wr]
            for n, name in enumerate(FINGERS):
                ids = [base + 3 * n + k for k in range(3)]
                if name == "thumb":
                    d, up = thumb_frame(s)
                    J[ids[0]] = W + np.array([s * 0.026, -0.011, 0.020]) * self.arm_len
                    lengths = THUMB_LENGTHS
                else:
                    zo, xo, spread, lengths, _, _ = LONG_FINGERS[name]
                    d = finger_dir(s, spread)
                    up = np.array([0.0, 1.0, 0.0]) - d[1] * d
                    up /= np.linalg.norm(up)
                    J[ids[0]] = W + np.array([s * xo, -0.003, zo + 0.002]) * self.arm_len
                lengths = np.array(lengths) * self.arm_len
                J[ids[1]] = J[ids[0]] + lengths[0] * d
                J[ids[2]] = J[ids[1]] + lengths[1] * d
                tip = J[ids[2]] + lengths[2] * d
                self.finger_frames[s, name] = (d, up, tip, lengths)
        return J  # unscaled; stature scales the finished mesh
