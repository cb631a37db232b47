"""What the stages of a run hand each other: `Bodies` (per-frame bodies and cameras), `Track` (one person over a
chunk of frames) and `Chunk` (every person of one chunk through the per-chunk stages, as stored for resume)."""

import dataclasses
from dataclasses import dataclass

import jax
import numpy as np

import smplx_jax


def frames_where(mask: np.ndarray, chosen, other):
    """Frame by frame (``mask (T,)``), ``chosen``'s leaves where true and ``other``'s elsewhere: two pytrees of
    per-frame arrays (`Bodies`, `Track`)."""
    return jax.tree.map(lambda a, b: np.where(mask.reshape((-1,) + (1,) * (a.ndim - 1)), a, b), chosen, other)


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Bodies:
    """``T`` frames: batched parameters, the weak-perspective camera (pixel = ``camera_scale * X[:2] +
    camera_trans``, the closest one when fitted through a pinhole) and where the body is ``valid``."""

    params: smplx_jax.SMPLXParams  # every leaf (T, ...)
    camera_scale: np.ndarray  # (T,)
    camera_trans: np.ndarray  # (T, 2)
    valid: np.ndarray  # (T,) bool

    @classmethod
    def concatenate(cls, parts: list["Bodies"]) -> "Bodies":
        return jax.tree.map(lambda *a: np.concatenate(a), *parts)


    @classmethod
    def absent(cls, count: int, model) -> "Bodies":
        """``count`` frames without the person: the rest pose, not valid."""
        rest = smplx_jax.SMPLXParams.zeros(model.num_betas, model.num_expression)
        params = jax.tree.map(lambda a: np.zeros((count,) + a.shape, np.float32), rest)
        return cls(params, np.ones(count, np.float32), np.zeros((count, 2), np.float32), np.zeros(count, bool))


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Track:
    """One person over the ``n`` frames of a chunk, after detection and the per-frame stages (the clip fit's start,
    or the regressors)."""

    keypoints_2d: np.ndarray  # (n, 67, 3) the fit's targets: OpenPose BODY_25 + hands, pixels, confidence
    body_box: np.ndarray  # (n, 4) x0, y0, x1, y1 pixels, NaN when missing
    hand_boxes: np.ndarray  # (n, 2, 4) left, right: the hand crops used, NaN when missing
    found: np.ndarray  # (n,) bool: the detector found the person
    body_world: np.ndarray  # (n, 33, 4) BlazePose's world landmarks (metres) and visibility
    hands_world: np.ndarray  # (n, 2, 21, 3) each hand's world landmarks (metres)
    hands_conf: np.ndarray  # (n, 2) each hand's presence, 0 when missing
    bodies: Bodies

    @classmethod
    def absent(cls, count: int, model) -> "Track":
        return cls(np.zeros((count, 67, 3), np.float32), np.full((count, 4), np.nan), np.full((count, 2, 4), np.nan),
                   np.zeros(count, bool), np.zeros((count, 33, 4), np.float32),
                   np.zeros((count, 2, 21, 3), np.float32), np.zeros((count, 2), np.float32),
                   Bodies.absent(count, model))

    @classmethod
    def concatenate(cls, parts: list["Track"]) -> "Track":
        return jax.tree.map(lambda *a: np.concatenate(a), *parts)


@dataclass(frozen=True)
class Chunk:
    """One chunk of frames: each person's `Track` by identity, what the detector, the identities and the camera's
    turns carry on to the next chunk (``tracking``), and each frame's camera turn
    (`jaxmocap.detect.camera_turns.CameraTurns.turns`)."""

    frame_index: np.ndarray  # (n,) frame numbers in the source
    people: dict[int, Track]
    tracking: dict[str, np.ndarray]
    scene_from_camera: np.ndarray  # (n, 3) axis-angles: the camera's axes turned into the scene's
    background_px: np.ndarray  # (n,) the background's stray from that turn, pixels (NaN: not measured)

    def arrays(self) -> dict[str, np.ndarray]:
        """Flat named arrays (the chunk file's keys: ``frame_index``, ``scene_from_camera``, ``background_px``,
        ``tracking/<key>``, ``<id>/<field>``)."""
        arrays = {"frame_index": self.frame_index, "scene_from_camera": self.scene_from_camera,
                  "background_px": self.background_px} | {f"tracking/{k}": v for k, v in self.tracking.items()}
        for person_id, track in self.people.items():
            leaves = {f.name: getattr(track, f.name) for f in dataclasses.fields(track) if f.name != "bodies"}
            leaves |= {k: getattr(track.bodies, k) for k in ("camera_scale", "camera_trans", "valid")}
            leaves |= {k: np.asarray(v) for k, v in vars(track.bodies.params).items()}
            arrays |= {f"{person_id}/{k}": v for k, v in leaves.items()}
        return arrays

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> "Chunk":
        tracking = {k.split("/", 1)[1]: v for k, v in arrays.items() if k.startswith("tracking/")}
        people = {}
        for person_id in sorted({int(k.split("/")[0]) for k in arrays if k.split("/")[0].isdigit()}):
            a = {k.split("/", 1)[1]: v for k, v in arrays.items() if k.startswith(f"{person_id}/")}
            params = smplx_jax.SMPLXParams(**{f.name: a[f.name] for f in dataclasses.fields(smplx_jax.SMPLXParams)})
            bodies = Bodies(params, a["camera_scale"], a["camera_trans"], a["valid"])
            people[person_id] = Track(a["keypoints_2d"], a["body_box"], a["hand_boxes"], a["found"], a["body_world"],
                                      a["hands_world"], a["hands_conf"], bodies)
        return cls(arrays["frame_index"], people, tracking, arrays["scene_from_camera"], arrays["background_px"])
