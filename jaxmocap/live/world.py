"""A live session's world frame (docs/formats.md, "World frame"), causal, for a still camera: the floor of the
bodies solved over the session's first `FLOOR_SECONDS` with someone in it, its normal the scene's vertical where
upright edges in `SCENE_FRAMES` of those frames show it (`integrate.ground.standing`, as `jaxmocap run` finds it),
found beside the solve (a thread: a second or two) and then held. From then on each frame's bodies get their world
keys (`LiveWorld.keys`), each heel and toe its contact from the frames up to it: at rest over the last
`ground.SPEED_WINDOW_S` and its sole within `ground.CONTACT_HEIGHT_M` of the floor. A recording's world keys are
its whole motion's on that floor (`world_columns`)."""

import threading
from collections import deque
from typing import NamedTuple

import jax
import numpy as np
from jaxtyping import Bool, Float

import smplx_jax
from jaxmocap.detect.verticals import images_vertical
from jaxmocap.integrate.clip import FOOT_JOINTS
from jaxmocap.integrate.ground import (
    CONTACT_HEIGHT_M,
    REST_SPEED_M_S,
    SPEED_WINDOW_S,
    Floor,
    at_rest,
    contacts,
    main_person,
    rest_pelvis,
    sole_heights,
    standing,
    world_frame,
    world_pose,
)
from jaxmocap.integrate.motion_arrays import body_joints
from jaxmocap.live.causal import Solved

# seconds of a session with someone in it before its floor is taken: two stances of a walk (0.3-0.6 s each) of
# resting heels and toes, or a person standing; the world keys start then
FLOOR_SECONDS = 1.0
SCENE_FRAMES = 5  # frames of those whose straight edges show the scene's vertical (as `jaxmocap run`'s)


class WorldKeys(NamedTuple):
    """One person's world keys in one frame (motion.npz's, one row)."""

    world_global_orient: Float[np.ndarray, "3"]
    world_transl: Float[np.ndarray, "3"]
    contact: Bool[np.ndarray, "4"]


class LiveWorld:
    """The world frame of a live session of a still camera through ``lens`` (its focal length ``fixed`` where the
    user gave it) on frames of ``long_side`` pixels (module docstring): each frame's solved bodies in it (`keys`);
    ``floor`` and ``camera_from_world`` once found (None before). The frame rate of its first second is the one it
    was solved at (frames may have been dropped)."""

    def __init__(self, model: smplx_jax.BodyModel, lens, long_side: float, fixed: bool = False):
        self.model, self.lens, self.long_side, self.fixed = model, lens, long_side, fixed
        self.floor: Floor | None = None
        self.camera_from_world: Float[np.ndarray, "4 4"] | None = None
        self.early: list[tuple[float, dict[int, Solved]]] = []  # the frames since someone was first seen
        self.images: list[tuple[float, np.ndarray]] = []  # `SCENE_FRAMES` of them
        self.finding: threading.Thread | None = None
        self.recent: dict[int, deque] = {}  # each person's (time, heels and toes) over the last SPEED_WINDOW_S
        self.above_sole: dict[int, tuple[bytes, np.ndarray]] = {}  # by identity: their shape's, for that shape

    def keys(self, now: float, solved: dict[int, Solved], image: np.ndarray) -> dict[int, WorldKeys]:
        """The world keys of the people ``solved`` in the frame ``image`` at ``now`` seconds, by identity (none
        before the floor is found: after the session's first `FLOOR_SECONDS` with someone in it)."""
        valid = {i: s for i, s in solved.items() if s.valid}
        if self.finding is None and (valid or self.early):
            self.early.append((now, valid))
            if not self.images or now - self.images[-1][0] >= FLOOR_SECONDS / SCENE_FRAMES:
                self.images.append((now, image))
            if now - self.early[0][0] >= FLOOR_SECONDS:
                self.finding = threading.Thread(target=self._stand, args=(self.early, self.images),
                                                name="jaxmocap-floor", daemon=True)
                self.finding.start()
                self.early, self.images = [], []
        if not valid:
            return {}
        params = jax.tree.map(lambda *a: np.stack([np.asarray(x) for x in a]), *(s.params for s in valid.values()))
        feet = body_joints(self.model, params)[:, FOOT_JOINTS]
        for person, foot in zip(valid, feet):
            recent = self.recent.setdefault(person, deque())
            recent.append((now, foot))
            while now - recent[0][0] > SPEED_WINDOW_S:
                recent.popleft()
        found = self.camera_from_world
        if found is None:
            return {}
        orient, transl = world_pose(params.global_orient, params.transl, rest_pelvis(self.model, params.betas)
                                    + params.transl, np.repeat(found[None], len(valid), 0))
        return {i: WorldKeys(orient[k].astype(np.float32), transl[k].astype(np.float32), self._contact(i, s, feet[k]))
                for k, (i, s) in enumerate(valid.items())}

    def warm_up(self) -> None:
        """Compile what one frame's keys run (the heels' and toes' joints), so that the first person's frame does
        not wait."""
        body_joints(self.model, jax.tree.map(lambda a: np.asarray(a)[None], smplx_jax.SMPLXParams.zeros(
            self.model.num_betas, self.model.num_expression)))

    def settle(self, timeout: float) -> None:
        """Wait for the floor being found (at most ``timeout`` seconds)."""
        if self.finding is not None:
            self.finding.join(timeout)

    def _contact(self, person: int, solved: Solved, feet: Float[np.ndarray, "4 3"]) -> Bool[np.ndarray, "4"]:
        """Which heels and toes rest on the floor now: slower than `REST_SPEED_M_S` since the oldest of the last
        `SPEED_WINDOW_S` (a person seen for less is not at rest), their soles within `CONTACT_HEIGHT_M` of it."""
        then, before = self.recent[person][0]
        elapsed = self.recent[person][-1][0] - then
        if elapsed < SPEED_WINDOW_S / 2:
            return np.zeros(4, bool)
        resting = np.linalg.norm(feet - before, axis=-1) < REST_SPEED_M_S * elapsed
        return resting & (self.floor.heights(feet) - self._above_sole(person, solved) < CONTACT_HEIGHT_M)

    def _above_sole(self, person: int, solved: Solved) -> np.ndarray:
        betas = np.asarray(solved.params.betas, np.float32)
        key = betas.tobytes()
        if self.above_sole.get(person, (None,))[0] != key:
            self.above_sole[person] = (key, sole_heights(self.model, betas))
        return self.above_sole[person][1]

    def _stand(self, early: list[tuple[float, dict[int, Solved]]], images: list[tuple[float, np.ndarray]]) -> None:
        """The floor and the world frame of the ``early`` frames (`integrate.ground.standing` of everyone in them,
        the scene's vertical from ``images``' edges; the origin under the person seen most, in their first
        frame)."""
        times = np.asarray([t for t, _ in early])
        fps = (len(times) - 1) / max(times[-1] - times[0], 1e-9)  # as solved: frames may have been dropped
        absent = smplx_jax.SMPLXParams.zeros(self.model.num_betas, self.model.num_expression)
        people = {}
        for person in sorted({i for _, frame in early for i in frame}):
            rows = [frame.get(person) for _, frame in early]
            params = jax.tree.map(lambda *a: np.stack([np.asarray(x, np.float32) for x in a]),
                                  *(absent if s is None else s.params for s in rows))
            people[person] = (params, np.asarray([s is not None for s in rows]))
        main = main_person({i: valid for i, (_, valid) in people.items()})
        ground = standing(self.model, people, fps, main, lambda near: images_vertical(
            [image for _, image in images], self.lens, near, self.long_side, self.fixed))
        params, valid = people[main]
        first = int(np.argmax(valid))
        self.floor = ground.floor
        self.camera_from_world = world_frame(ground.floor, rest_pelvis(self.model, params.betas[first:first + 1])[0]
                                             + params.transl[first])  # (set last: `keys` reads it first)


def world_columns(model: smplx_jax.BodyModel, world: LiveWorld, motion: dict[str, np.ndarray], fps: float
                  ) -> dict[str, np.ndarray]:
    """A recorded person's world keys over their whole ``motion`` (its ``global_orient``, ``transl``, ``betas``,
    ``valid`` and ``feet (T, 4, 3)``, the heels and toes in the camera's frame) on ``world``'s floor (none before it
    is found): contacts as `jaxmocap run` finds them (at rest about each frame, near the floor)."""
    found = world.camera_from_world  # (set after the floor)
    if found is None:
        return {}
    frames, valid = len(motion["valid"]), np.asarray(motion["valid"], bool)
    transl = np.asarray(motion["transl"], np.float64)
    camera_from_world = np.repeat(found[None], frames, 0)
    orient, world_transl = world_pose(motion["global_orient"], transl,
                                      rest_pelvis(model, motion["betas"]) + transl, camera_from_world)
    above = sole_heights(model, motion["betas"][np.argmax(valid)]) if valid.any() else np.zeros(4)
    feet = np.asarray(motion["feet"], np.float64)
    contact = contacts(feet, above, at_rest(feet, valid, fps), world.floor) & valid[:, None]
    return {"world_global_orient": orient.astype(np.float32), "world_transl": world_transl.astype(np.float32),
            "camera_from_world": camera_from_world.astype(np.float32),
            "floor": world.floor.array.astype(np.float32), "contact": contact}
