"""What the stages of a run hand each other: `Bodies` (per-frame bodies and cameras) and `Chunk` (one chunk of
frames through the per-chunk stages, as stored for resume)."""

import dataclasses
from dataclasses import dataclass

import jax
import numpy as np

import smplx_jax


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


@dataclass(frozen=True)
class Chunk:
    """One chunk of ``n`` frames after detection and the fit (or the regressors)."""

    frame_index: np.ndarray  # (n,) frame numbers in the source
    keypoints_2d: np.ndarray  # (n, 67, 3) the fit's targets: OpenPose BODY_25 + hands, pixels, confidence
    body_box: np.ndarray  # (n, 4) x0, y0, x1, y1 pixels, NaN when missing
    hand_boxes: np.ndarray  # (n, 2, 4) left, right: the hand crops used, NaN when missing
    found: np.ndarray  # (n,) bool: the detector found a person
    bodies: Bodies

    def arrays(self) -> dict[str, np.ndarray]:
        """Flat named arrays (the chunk file's keys)."""
        own = {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "bodies"}
        cameras = {k: getattr(self.bodies, k) for k in ("camera_scale", "camera_trans", "valid")}
        return own | cameras | {k: np.asarray(v) for k, v in vars(self.bodies.params).items()}

    @classmethod
    def from_arrays(cls, arrays: dict[str, np.ndarray]) -> "Chunk":
        params = smplx_jax.SMPLXParams(**{f.name: arrays[f.name] for f in dataclasses.fields(smplx_jax.SMPLXParams)})
        bodies = Bodies(params, arrays["camera_scale"], arrays["camera_trans"], arrays["valid"])
        return cls(arrays["frame_index"], arrays["keypoints_2d"], arrays["body_box"], arrays["hand_boxes"],
                   arrays["found"], bodies)
