"""Batched, jitted inference with fixed batch buckets: a batch is padded to the next bucket (and split above
the largest), so ragged batches reuse a handful of compiled functions."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx
from jaxtyping import Array, ArrayLike, Float

from jaxmocap.buckets import map_in_buckets, pad_rows, padded_size
from jaxmocap.regressors import crops as _crops
from jaxmocap.regressors.body import BodyOutput
from jaxmocap.regressors.weights import Regressors

BUCKETS = (1, 4, 16, 64)
CPU_MICROBATCH = 8  # batch 64 runs faster as 8 chunks of 8 than in one piece on CPUs (docs/BENCHMARKS.md, Regressors)


@functools.partial(jax.jit, static_argnums=(0, 3))
def _apply(graphdef, state, images, microbatch):
    network = nnx.merge(graphdef, state)
    n = images.shape[0]
    if n <= microbatch or n % microbatch:
        return network(images)
    # Sequential chunks inside one compiled call keep a chunk's activations in cache (faster on CPUs).
    out = jax.lax.map(network, images.reshape((n // microbatch, microbatch) + images.shape[1:]))
    return jax.tree.map(lambda a: a.reshape((n,) + a.shape[2:]), out)


class Predictor:
    """Pure forward passes of both networks: ``predictor.hand(crops)`` -> ``(N, 61)``, ``predictor.body(crops)``
    -> `BodyOutput`. Inputs are normalised crops ``(N, 224, 224, 3)``; N may be anything, 0 included.

    ``microbatch`` runs a larger bucket as sequential chunks of that size inside its compiled call (activations
    stay in cache); default `CPU_MICROBATCH` on a CPU, whole buckets on accelerators.
    """

    def __init__(self, regressors: Regressors, buckets: tuple[int, ...] = BUCKETS, microbatch: int | None = None):
        if not buckets or any(b < 1 for b in buckets):
            raise ValueError(f"buckets: expected positive batch sizes, got {buckets}")
        if microbatch is not None and microbatch < 1:
            raise ValueError(f"microbatch: expected a positive batch size or None, got {microbatch}")
        self.buckets = tuple(sorted(buckets))
        self.microbatch = microbatch or (CPU_MICROBATCH if jax.default_backend() == "cpu" else self.buckets[-1])
        self._hand = nnx.split(regressors.hand)
        self._body = nnx.split(regressors.body)

    @property
    def body_network(self) -> tuple[nnx.GraphDef, nnx.State]:
        """The body regressor split into graph and weights (to fine-tune copies of it: `integrate.eft`)."""
        return self._body

    def hand(self, crops: Float[ArrayLike, "N 224 224 3"]) -> Float[Array, "N 61"]:
        return self._run(self._hand, crops, jnp.zeros((0, 61), jnp.float32))

    def body(self, crops: Float[ArrayLike, "N 224 224 3"]) -> BodyOutput:
        empty = BodyOutput(jnp.zeros((0, 24, 3, 3), jnp.float32), jnp.zeros((0, 10), jnp.float32),
                           jnp.zeros((0, 3), jnp.float32))
        return self._run(self._body, crops, empty)

    def _run(self, split, crops, empty):
        crops = jnp.asarray(crops, jnp.float32)
        if crops.ndim != 4 or crops.shape[-1] != 3:
            raise ValueError(f"crops: expected (N, H, W, 3), got shape {crops.shape}")
        if crops.shape[0] == 0:
            return empty
        return map_in_buckets(lambda batch, _: _apply(*split, batch, self.microbatch), crops, self.buckets)


def predict_hands(predictor: Predictor, images, frame, boxes, is_left):
    """Hands of many frames in one batch: ``images (F, H, W, 3)`` uint8 BGR, per hand its ``frame`` index, box
    ``(x, y, w, h)`` (a NaN row where the hand is missing: its crop is skipped) and ``is_left``.

    Returns ``(raw (N, 61), window, valid (N,))``; ``raw`` is as the network outputs it for the right-hand
    (left ones flipped) crop, NaN where not ``valid``. Decode with `decode.decode_hands`.
    """
    boxes = np.asarray(boxes, np.float64)
    present = np.all(np.isfinite(boxes), axis=-1)
    window = _crops.hand_windows(np.where(present[:, None], boxes, 0.0), images.shape[2:0:-1])
    return _predict(predictor, "hand", images, frame, window, present, is_left)


def predict_bodies(predictor: Predictor, images, frame, boxes):
    """Bodies of many frames in one batch, as `predict_hands`; returns ``(BodyOutput, window, valid)``."""
    boxes = np.asarray(boxes, np.float64)
    present = np.all(np.isfinite(boxes), axis=-1)
    window = _crops.body_windows(np.where(present[:, None], boxes, 0.0), images.shape[2:0:-1])
    return _predict(predictor, "body", images, frame, window, present, False)


def _predict(predictor, kind, images, frame, window, present, flip):
    valid = present & window.ok
    keep = np.flatnonzero(valid)
    n, m = len(valid), len(keep)
    batch = np.zeros((0, 224, 224, 3))
    if m:  # crop a bucket-sized batch too (repeating a kept crop), so cropping does not recompile either
        rows = pad_rows(keep, padded_size(m, predictor.buckets))
        frame = np.broadcast_to(np.asarray(frame, np.int32), (n,))
        flip = np.broadcast_to(np.asarray(flip, bool), (n,))
        sub = _crops.Window(*(np.asarray(a)[rows] for a in window))
        normalize = _crops.normalize_hand if kind == "hand" else _crops.normalize_body
        batch = normalize(_crops.crop(images, frame[rows], sub, flip[rows]))
    out = getattr(predictor, kind)(batch)
    full = jax.tree.map(lambda a: jnp.full((n,) + a.shape[1:], jnp.nan, a.dtype).at[keep].set(a[:m]), out)
    return full, window, valid
