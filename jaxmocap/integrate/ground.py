"""The floor under a clip and the world frame standing on it (DESIGN 2.3, "World frame").

Everything here is in the scene's frame: the camera's where it is static, else the axes of a camera that does not
turn (the first frame's; ``scene_from_camera``, each frame's turn, `jaxmocap.detect.camera_turns`), its centre the
camera's. The world frame is fixed in the scene, so a turning camera's ``camera_from_world`` turns with it.

The floor's normal is the scene's vertical where its upright edges show it (`jaxmocap.detect.verticals`: a fraction
of a degree through the right lens). Without them it is fitted to the feet: a foot carrying weight is at rest, on
the floor, so the floor is the plane of the soles under the heels and toes while they rest (`floor_planes`; each
joint stands its own height above its sole, `sole_heights`), its normal drawn towards the torsos' mean up direction
(people stand and walk upright), which decides it where the resting feet span too little of the floor to tilt a
plane; a monocular fit's feet tilt it by tens of degrees where a person stays in one place. The floor's height is
the resting soles' either way, each person's fit at its own (their scale, which one view cannot see, moves it), the
scene's the main person's; the others are lowered or raised onto it in the world. The world frame
(`world_frame`): y up along the floor's normal, the floor (the soles' plane) y = 0, z the scene's forward direction
along the floor, the origin on the floor under the main person's pelvis in their first valid frame. `standing` finds
the floor and the feet's contacts of a clip's motion (the clip fit is then refitted on them: `ClipGround`),
`world_arrays` its motion.npz world keys.
"""

import math
from typing import NamedTuple

import numpy as np
from jaxtyping import Bool, Float, Int
from scipy.spatial.transform import Rotation

import smplx_jax
from jaxmocap.integrate.clip import FOOT_JOINTS, ClipGround
from jaxmocap.integrate.motion_arrays import body_joints

PELVIS, NECK = 0, 12
# A stepping foot moves at 1-4 m/s and one carrying weight not at all: below this speed a heel or toe may carry
# weight. Its speed is its displacement over `SPEED_WINDOW_S`, long enough to average out a fit's frame-to-frame
# noise (some millimetres) and short enough to see a step (0.3-0.6 s a stance).
REST_SPEED_M_S = 0.25
SPEED_WINDOW_S = 0.2
CONTACT_HEIGHT_M = 0.05  # a resting sole this close to the floor (or below it) touches it: a monocular fit's depth
# noise, some centimetres, moves a sole that far
MIN_HEIGHT_NOISE_M = 0.01  # resting soles stray at least this far from one plane (a foot flexes, a floor is uneven)
UP_LEAN_RAD = math.radians(15.0)  # how far the torsos' mean direction over a clip leans from the vertical
PLANE_ITERATIONS = 5  # refits with the points found touching the floor (it settles in two or three)


class Floor(NamedTuple):
    """The plane ``normal · X + offset = 0`` in the scene's frame (metres), ``normal`` the unit up direction."""

    normal: Float[np.ndarray, "3"]
    offset: float

    def heights(self, points: Float[np.ndarray, "*n 3"]) -> Float[np.ndarray, "*n"]:
        return np.asarray(points @ self.normal + self.offset)

    @property
    def array(self) -> Float[np.ndarray, "4"]:
        """motion.npz's ``floor (4,)``: ``(nx, ny, nz, d)``."""
        return np.append(self.normal, self.offset)


def sole_heights(model: smplx_jax.BodyModel, betas: Float[np.ndarray, "B"]) -> Float[np.ndarray, "4"]:
    """How far each heel and toe joint (`FOOT_JOINTS`, vertices of the mesh) stands above the soles in the rest
    pose (feet flat), for the shape ``betas``: the shaped template's, which the rest pose leaves as it is."""
    shaped = np.asarray(model.template_cm, np.float64) + (
        np.asarray(betas, np.float64) @ np.asarray(model.shapedirs_cm, np.float64)[:model.num_betas]).reshape(3, -1)
    feet = [smplx_jax.constants.VERTEX_JOINT_IDS[joint - 55] for joint in FOOT_JOINTS]
    return shaped[1, feet] - shaped[1].min()


def rest_pelvis(model: smplx_jax.BodyModel, betas: Float[np.ndarray, "T B"]) -> Float[np.ndarray, "T 3"]:
    """The pelvis joint of each shape ``betas`` at rest (no pose, no ``transl``): the point the root turns about,
    so that a body's pelvis is this plus its ``transl`` whatever its pose."""
    betas = np.asarray(betas, np.float64)
    shapedirs = np.asarray(model.joint_shapedirs, np.float64)[0, :, :betas.shape[-1]]
    return np.asarray(model.joint_template, np.float64)[0] + betas @ shapedirs.T


def at_rest(feet: Float[np.ndarray, "T 4 3"], valid: Bool[np.ndarray, "T"], fps: float) -> Bool[np.ndarray, "T 4"]:
    """Which heels and toes move slower than `REST_SPEED_M_S` (over `SPEED_WINDOW_S` about each frame, valid frames
    only; frames without a valid one that far on either side are not at rest)."""
    half = max(1, round(SPEED_WINDOW_S * fps / 2))
    t = np.arange(len(valid))
    before, after = np.clip(t - half, 0, len(t) - 1), np.clip(t + half, 0, len(t) - 1)
    seen = valid & valid[before] & valid[after] & (after > before)
    speed = np.linalg.norm(feet[after] - feet[before], axis=-1) * fps / np.maximum(after - before, 1)[:, None]
    return seen[:, None] & (speed < REST_SPEED_M_S)


def torso_up(joints: Float[np.ndarray, "T 127 3"], valid: Bool[np.ndarray, "T"]) -> Float[np.ndarray, "3"]:
    """The mean direction from pelvis to neck over the valid frames (unit)."""
    spine = joints[valid, NECK] - joints[valid, PELVIS]
    mean = (spine / np.linalg.norm(spine, axis=-1, keepdims=True)).sum(0)
    return mean / np.linalg.norm(mean)


def stance_weights(resting: Bool[np.ndarray, "T K"]) -> Float[np.ndarray, "T K"]:
    """Each resting frame's share of its stance (1 / the frames of its run of rest), 0 elsewhere: a heel or toe
    resting for many frames is one observation of the floor (its fitted position's errors hold from frame to frame),
    not many."""
    weights = np.zeros(resting.shape)
    for k in range(resting.shape[1]):
        edges = np.diff(np.r_[0, resting[:, k].astype(int), 0])
        for start, stop in zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)):
            weights[start:stop, k] = 1.0 / (stop - start)
    return weights


def floor_planes(feet: Float[np.ndarray, "N 3"], above_sole: Float[np.ndarray, "N"], weights: Float[np.ndarray, "N"],
                 person: Int[np.ndarray, "N"], up: Float[np.ndarray, "3"], known_up: bool = False) -> list[Floor]:
    """The floor under the resting heels and toes of people ``0..P-1`` (``person``: each point's; camera frame;
    each ``above_sole`` metres above its sole, each weighed by ``weights``: 0 where not resting, `stance_weights`),
    its normal pointing ``up``'s way, as each person's fit stands on it: one plane each, all parallel. A monocular
    fit's scale (its depth along the rays: mostly the stature it cannot see, some per cent) scales a person's
    positions about the camera, which moves the plane of their soles along its normal and never turns it: a person
    seen a tenth too far stands a tenth of the camera's height below the others. The normal is fitted to everyone's
    soles, each person's about their own centre: the soles' heights weighed against their spread about their plane
    (at least `MIN_HEIGHT_NOISE_M`), the normal's lean from ``up`` against `UP_LEAN_RAD` (a Gaussian maximum a
    posteriori plane); refitted with the soles within `CONTACT_HEIGHT_M` of their plane. ``known_up``: the normal is
    ``up`` (the scene's vertical), only the heights fitted. A person without resting points: the plane under the
    lowest tenth of their soles."""
    up = np.asarray(up, np.float64) / np.linalg.norm(up)
    feet, above_sole = np.asarray(feet, np.float64), np.asarray(above_sole, np.float64)
    person, weights = np.asarray(person), np.asarray(weights, np.float64)
    groups = [person == p for p in range(int(person.max(initial=-1)) + 1)]
    resting = weights > 0
    normal = up
    offsets = np.array([-float(np.median(feet[g & resting] @ up - above_sole[g & resting])) if (g & resting).any()
                        else _lowest(feet[g] @ up - above_sole[g]) for g in groups])
    prior = (np.eye(3) - np.outer(up, up)) / UP_LEAN_RAD**2
    for _ in range(PLANE_ITERATIONS if resting.any() else 0):
        soles = feet - above_sole[:, None] * normal  # (a resting foot is flat: its sole straight below)
        heights = soles @ normal + offsets[person]
        touching = resting & (np.abs(heights) < CONTACT_HEIGHT_M)
        w = np.zeros(len(feet))
        for g in groups:  # a person's soles touching their plane (all their resting ones where fewer than 3 do)
            w[g] = np.where((touching if (touching & g).sum() >= 3 else resting)[g], weights[g], 0.0)
        seen = np.array([w[g].sum() > 0 for g in groups])
        centres = np.stack([w[g] @ soles[g] / w[g].sum() if s else np.zeros(3) for g, s in zip(groups, seen)])
        about = soles - centres[person]
        noise = max(MIN_HEIGHT_NOISE_M, float(np.sqrt(w @ heights**2 / w.sum())))
        spread = (w[:, None] * about).T @ about / noise**2
        normal = up if known_up else np.linalg.eigh(spread + prior)[1][:, 0]  # the smallest eigenvalue's
        normal = normal if normal @ up > 0 else -normal
        offsets = np.array([-float(normal @ c) if s else _lowest(feet[g] @ normal - above_sole[g])
                            for g, c, s in zip(groups, centres, seen)])
    return [Floor(normal, float(offset)) for offset in offsets]


def _lowest(heights: Float[np.ndarray, "n"]) -> float:
    """The offset of the plane under the lowest tenth of ``heights`` (0 without any)."""
    return -float(np.quantile(heights, 0.1)) if len(heights) else 0.0


def world_frame(floor: Floor, origin: Float[np.ndarray, "3"]) -> Float[np.ndarray, "4 4"]:
    """``scene_from_world`` (a static camera's ``camera_from_world``): y up along the floor's normal, z the scene's
    forward direction along the floor (its x where it looks straight down), x = y × z; the origin the floor's point
    under ``origin`` (the scene's frame)."""
    y = floor.normal
    forward = np.array([0.0, 0.0, 1.0]) - y[2] * y
    if np.linalg.norm(forward) < 1e-3:  # looking straight down: z along the camera's x
        forward = np.array([1.0, 0.0, 0.0]) - y[0] * y
    z = forward / np.linalg.norm(forward)
    x = np.cross(y, z)
    transform = np.eye(4)
    transform[:3, :3] = np.stack([x, y, z], axis=1)
    transform[:3, 3] = origin - floor.heights(origin) * y
    return transform


def contacts(feet: Float[np.ndarray, "T 4 3"], above_sole: Float[np.ndarray, "4"], resting: Bool[np.ndarray, "T 4"],
             floor: Floor) -> Bool[np.ndarray, "T 4"]:
    """motion.npz's ``contact``: a heel or toe at rest whose sole is within `CONTACT_HEIGHT_M` of the floor, or
    below it."""
    return resting & (floor.heights(feet) - above_sole < CONTACT_HEIGHT_M)


def world_pose(global_orient: Float[np.ndarray, "T 3"], transl: Float[np.ndarray, "T 3"],
               pelvis: Float[np.ndarray, "T 3"], camera_from_world: Float[np.ndarray, "T 4 4"]):
    """``(world_global_orient, world_transl)``: the body in the world frame, from each frame's camera. The root
    turns about the rest pelvis ``J0 = pelvis - transl`` (its camera-frame position less ``transl``), so
    ``world_transl`` is ``R^T (pelvis - t) - J0``. A frame whose orientation is not finite gives NaN."""
    rotation, t = camera_from_world[:, :3, :3], camera_from_world[:, :3, 3]
    global_orient = np.asarray(global_orient, np.float64)
    finite = np.isfinite(global_orient).all(1)
    root = Rotation.from_rotvec(np.where(finite[:, None], global_orient, 0.0)).as_matrix()
    world_orient = np.where(finite[:, None], Rotation.from_matrix(np.swapaxes(rotation, 1, 2) @ root).as_rotvec(),
                            np.nan)
    return world_orient, np.einsum("tji,tj->ti", rotation, pelvis - t) - (pelvis - transl)


def in_scene(points: Float[np.ndarray, "T *K 3"], scene_from_camera: Float[np.ndarray, "T 3"] | None
             ) -> Float[np.ndarray, "T *K 3"]:
    """Each frame's camera-frame ``points`` in the scene's frame (None: a static camera's, as they are)."""
    if scene_from_camera is None:
        return points
    turn = Rotation.from_rotvec(np.asarray(scene_from_camera, np.float64)).as_matrix()
    return np.einsum("tij,t...j->t...i", turn, points)


def cameras_from_world(scene_from_world: Float[np.ndarray, "4 4"], frames: int,
                       scene_from_camera: Float[np.ndarray, "T 3"] | None) -> Float[np.ndarray, "T 4 4"]:
    """Each frame's ``camera_from_world``: the scene's transform seen from that frame's camera."""
    camera_from_scene = np.repeat(np.eye(4)[None], frames, 0)
    if scene_from_camera is not None:
        turn = Rotation.from_rotvec(np.asarray(scene_from_camera, np.float64)).as_matrix()
        camera_from_scene[:, :3, :3] = np.swapaxes(turn, 1, 2)
    return camera_from_scene @ scene_from_world


def camera_floors(camera_from_world: Float[np.ndarray, "T 4 4"]) -> Float[np.ndarray, "T 4"]:
    """Each frame's floor (the world's y = 0) in its camera's frame, ``(nx, ny, nz, d)`` as motion.npz's."""
    up = camera_from_world[:, :3, 1]
    return np.concatenate([up, -np.sum(up * camera_from_world[:, :3, 3], 1, keepdims=True)], 1)


def main_person(valid: dict[int, Bool[np.ndarray, "T"]]) -> int | None:
    """The person valid in most frames (``valid``: by identity; the first seen of those tied), whom the scene's
    floor and world frame belong to (motion.npz's person); None without anyone."""
    return max(valid, key=lambda i: (int(np.sum(valid[i])), -i), default=None)


class Standing(NamedTuple):
    """The floor under a clip's people (`standing`): the scene's (``floor``: where the main person stands) and, by
    identity, the plane each one's fit stands on (``planes``: parallel to it, `floor_planes`), their heels' and
    toes' heights above their soles (`sole_heights`) and their contacts with their plane (`contacts`, ``(T, 4)``)."""

    floor: Floor
    planes: dict[int, Floor]
    above_sole: dict[int, Float[np.ndarray, "4"]]
    contact: dict[int, Bool[np.ndarray, "T 4"]]

    def clip_ground(self, person: int) -> ClipGround:
        """What the clip fit of ``person`` stands on (`jaxmocap.integrate.clip.ClipGround`): their plane."""
        return ClipGround(self.planes[person].array.astype(np.float32), self.above_sole[person].astype(np.float32),
                          self.contact[person].astype(np.float32), np.float32(1.0))

    def raised(self, person: int) -> float:
        """How far ``person``'s plane lies above the scene's floor (metres; 0 for the main person): the world keys
        lower them by it, onto the floor."""
        return self.floor.offset - self.planes[person].offset


def standing(model: smplx_jax.BodyModel, people: dict[int, tuple[smplx_jax.SMPLXParams, np.ndarray]], fps: float,
             main: int | None, scene_up=None, scene_from_camera: Float[np.ndarray, "T 3"] | None = None
             ) -> Standing | None:
    """The floor under everyone of a clip (the scene's frame) and their feet's contacts with it, from their bodies
    in the camera's frame and where they are valid (``people``: by identity), each frame's camera turned into the
    scene's axes by ``scene_from_camera`` (None: a static camera); None without a valid frame. Each person's fit
    stands on a plane of its own, parallel to the others (`floor_planes`); the scene's floor is ``main``'s (the
    first person seen where ``main`` is None or not seen). ``scene_up(near)``: the scene's vertical near the torsos' up
    (`jaxmocap.detect.verticals`; the scene's axes), or None: where it gives one, it is the floor's normal (its
    edges hold it to a fraction of a degree; a monocular fit's resting feet, to several)."""
    valid = {i: np.asarray(v, bool) for i, (_, v) in people.items()}
    seen = [i for i in people if valid[i].any()]
    if not seen:
        return None
    joints = {i: in_scene(body_joints(model, params), scene_from_camera) for i, (params, _) in people.items()}
    feet = {i: j[:, FOOT_JOINTS] for i, j in joints.items()}
    resting = {i: at_rest(feet[i], valid[i], fps) for i in people}
    above = {i: sole_heights(model, params.betas[np.argmax(valid[i])]) if i in seen else np.zeros(4)
             for i, (params, _) in people.items()}
    up = torso_up(np.concatenate([joints[i] for i in seen]), np.concatenate([valid[i] for i in seen]))
    vertical = None if scene_up is None else scene_up(up)
    planes = floor_planes(np.concatenate([feet[i][valid[i]].reshape(-1, 3) for i in seen]),
                          np.concatenate([np.tile(above[i], int(valid[i].sum())) for i in seen]),
                          np.concatenate([stance_weights(resting[i])[valid[i]].ravel() for i in seen]),
                          np.concatenate([np.full(4 * int(valid[i].sum()), k) for k, i in enumerate(seen)]),
                          up if vertical is None else vertical, known_up=vertical is not None)
    planes = dict(zip(seen, planes))
    planes |= {i: planes[seen[0]] for i in people if i not in planes}
    return Standing(planes[main if main in seen else seen[0]], planes, above,
                    {i: contacts(feet[i], above[i], resting[i], planes[i]) for i in people})


def world_arrays(model: smplx_jax.BodyModel, people: dict[int, tuple[smplx_jax.SMPLXParams, np.ndarray]],
                 main: int, ground: Standing, scene_from_camera: Float[np.ndarray, "T 3"] | None = None
                 ) -> dict[int, dict[str, np.ndarray]]:
    """Each person's motion.npz world keys (``world_global_orient``, ``world_transl``, ``camera_from_world``,
    ``floor`` (the scene's frame: the first frame's camera's), ``contact``) from their bodies in the camera's frame
    and where they are valid (``people``: by identity), each frame's camera turned into the scene's axes by
    ``scene_from_camera`` (None: a static camera), standing on ``ground`` (`standing` of these people), the origin
    under ``main`` (or the first valid person)."""
    valid = {i: np.asarray(v, bool) for i, (_, v) in people.items()}
    first = main if valid[main].any() else next(i for i in people if valid[i].any())
    pelvis = {i: rest_pelvis(model, params.betas) + params.transl for i, (params, _) in people.items()}
    start = np.argmax(valid[first])
    origin = in_scene(pelvis[first][start:start + 1], None if scene_from_camera is None else
                      np.asarray(scene_from_camera)[start:start + 1])[0]
    camera_from_world = cameras_from_world(world_frame(ground.floor, origin), len(valid[first]), scene_from_camera)
    out = {}
    for i, (params, _) in people.items():
        orient, transl = world_pose(params.global_orient, params.transl, pelvis[i], camera_from_world)
        transl[:, 1] -= ground.raised(i)  # each on the floor from their own plane (`Standing.raised`)
        out[i] = {"world_global_orient": orient.astype(np.float32), "world_transl": transl.astype(np.float32),
                  "camera_from_world": camera_from_world.astype(np.float32),
                  "floor": ground.floor.array.astype(np.float32), "contact": ground.contact[i]}
    return out
