"""Exemplar fine-tuning (EFT; Joo, Neverova, Vedaldi 2021): fit the body regressor itself to one frame's 2D keypoints.

    graphdef, state = nnx.split(regressors.body)
    result = fine_tune(graphdef, state, crops, keypoints, model)   # crops (N, 224, 224, 3) normalised RGB
    result.output, result.initial_error_px, result.error_px        # keypoints (N, 25, 3): BODY_25 crop pixels, conf

Every frame gets its own copy of the trainable weights and ``steps`` Adam updates (``jax.vmap`` over frames of a
``lax.scan`` of steps); the given weights are never changed. BatchNorm keeps its running statistics and its scale and
shift are frozen, as in EFT. The loss is EFT's, in the crop's normalised coordinates (``pixel / 112 - 1``):
``60 (5 L_2D + 0.001 mean(betas^2) + exp(-10 s)^2 + 0.005 L_leg)`` with L_2D SPIN's confidence-weighted squared
error (hips and ankles left out, as EFT does) and L_leg ``1 - cos`` between the predicted and target knee-to-ankle
directions. ``trainable`` picks what is fine-tuned: ``"all"`` (EFT: the whole network), ``"layer4"`` (the last ResNet
stage and the heads; layer1-3 run once, shared) or ``"head"`` (the regression heads on features computed once).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import nnx
from jaxtyping import Array, ArrayLike, Float

import smplx_jax
from jaxmocap.regressors.body import BodyOutput, BodyRegressor
from jaxmocap.regressors.crops import SIZE
from jaxmocap.regressors.decode import body_params
from smplx_jax import constants

TRAINABLE = ("all", "layer4", "head")
# Adam moves each weight by about the learning rate whatever the loss scale, so EFT's 5e-6 carries over for the
# whole network. Heads alone: 1e-5 measured best of 1e-4 (diverges) .. 3e-7 on random-weight ResNet-50 and
# ResNet-18 regressors (sample clip and synthetic targets); layer4 takes the same (not tuned separately).
LEARNING_RATES = {"all": 5e-6, "layer4": 1e-5, "head": 1e-5}
HALF = SIZE / 2
LEG_MIN_LENGTH = 0.0089  # EFT: target shins shorter than this (normalised units, ~1 crop pixel) carry no direction
_HEADS = ("fc1", "fc2", "decpose", "decshape", "deccam")
_BODY25 = np.asarray(constants.BODY25_FROM_SMPLX)
# BODY_25: hips (mid 8, right 9, left 12) and ankles (11, 14) are not position targets (EFT); shins give direction.
POSITION_WEIGHTS = np.ones(25, np.float32)
POSITION_WEIGHTS[[8, 9, 12, 11, 14]] = 0.0
SHINS = ((10, 11), (13, 14))  # (knee, ankle): right, left


@dataclasses.dataclass(frozen=True)
class EFTConfig:
    """Static settings (hashable: a change recompiles). ``learning_rate`` None: `LEARNING_RATES[trainable]`."""

    trainable: str = "head"
    steps: int = 20
    learning_rate: float | None = None
    keypoint_weight: float = 5.0
    betas_weight: float = 1e-3
    leg_weight: float = 5e-3

    def __post_init__(self):
        if self.trainable not in TRAINABLE:
            raise ValueError(f"trainable: expected one of {TRAINABLE}, got {self.trainable!r}")
        if self.steps < 1:
            raise ValueError(f"steps: expected at least 1, got {self.steps}")

    @property
    def rate(self) -> float:
        return LEARNING_RATES[self.trainable] if self.learning_rate is None else self.learning_rate


class EFTResult(NamedTuple):
    """Fine-tuned predictions and the mean crop-pixel distance of the BODY_25 keypoints with confidence > 0
    (0 where none), before and after."""

    output: BodyOutput
    initial_error_px: Float[Array, "N"]
    error_px: Float[Array, "N"]


def _is_trainable(trainable: str):
    def keep(path, variable) -> bool:
        if not isinstance(variable, nnx.Param):
            return False
        if path[0] in _HEADS:
            return True
        # Convolution kernels only: BatchNorm's scale and shift stay frozen.
        return path[0] == "encoder" and path[-1] == "kernel" and (trainable == "all" or path[1] == "layer4")
    return keep


def _shared(network: BodyRegressor, crops, trainable: str):
    """What the frozen part of the network computes once for all frames."""
    if trainable == "head":
        return network.encoder(crops)
    if trainable == "layer4":
        return network.encoder.stages(network.encoder.stem(crops), 1, 3)
    return crops


def _predict(network: BodyRegressor, x, trainable: str) -> BodyOutput:
    """The fine-tuned part of the network on one frame's share ``x`` (leading axis 1)."""
    if trainable == "head":
        features = x
    elif trainable == "layer4":
        features = jnp.mean(network.encoder.stages(x, 4, 4), axis=(1, 2))
    else:
        features = network.encoder(x)
    return network.regress(features)


def _keypoints(model, rotmats, betas, camera) -> Float[Array, "25 2"]:
    """Projected BODY_25 in normalised crop coordinates."""
    joints = smplx_jax.forward_joints(model, body_params(model, rotmats, betas))[_BODY25]
    return joints[:, :2] * camera[0] + camera[1:]


def _unit(v, min_length):
    length2 = jnp.sum(v * v)
    ok = length2 > min_length ** 2
    return v / jnp.sqrt(jnp.where(ok, length2, 1.0)), ok


def loss(model, output: BodyOutput, target: Float[Array, "25 2"], conf: Float[Array, "25"], config: EFTConfig):
    """EFT's loss of one frame's prediction (``output`` without batch axis); ``target`` normalised, ``conf`` >= 0."""
    rotmats, betas, camera = output
    pred = _keypoints(model, rotmats, betas, camera)
    weight = conf * POSITION_WEIGHTS
    keypoints = jnp.sum(weight[:, None] * (pred - target) ** 2) / pred.size
    leg = 0.0
    for knee, ankle in SHINS:
        want, long_enough = _unit(target[ankle] - target[knee], LEG_MIN_LENGTH)
        have, _ = _unit(pred[ankle] - pred[knee], 0.0)
        leg += jnp.where(long_enough, conf[knee] * conf[ankle] * (1.0 - jnp.dot(want, have)), 0.0)
    return 60.0 * (config.keypoint_weight * keypoints + config.betas_weight * jnp.mean(betas ** 2)
                   + jnp.exp(-10.0 * camera[0]) ** 2 + config.leg_weight * leg)


def _error_px(model, output: BodyOutput, target, conf):
    pred = _keypoints(model, *output)
    seen = conf > 0
    dist = jnp.linalg.norm((pred - target) * HALF, axis=-1)
    return jnp.sum(jnp.where(seen, dist, 0.0)) / jnp.maximum(jnp.sum(seen), 1)


def _one(graphdef, trainable, frozen, model, x, target, conf, rate, config: EFTConfig):
    """``config.steps`` Adam steps on one frame's copy of ``trainable``; returns the final prediction."""
    optimizer = optax.adam(rate)
    def first(out):
        return jax.tree.map(lambda a: a[0], out)

    def predict(weights):
        return first(_predict(nnx.merge(graphdef, weights, frozen), x[None], config.trainable))

    def step(carry, _):
        weights, opt_state = carry
        grads = jax.grad(lambda w: loss(model, predict(w), target, conf, config))(weights)
        updates, opt_state = optimizer.update(grads, opt_state, weights)
        return (optax.apply_updates(weights, updates), opt_state), None

    (weights, _), _ = jax.lax.scan(step, (trainable, optimizer.init(trainable)), length=config.steps)
    return predict(weights)


@functools.partial(jax.jit, static_argnums=(0,), static_argnames=("config",))
def _fine_tune(graphdef, state, crops, keypoints, model, rate, config: EFTConfig) -> EFTResult:
    network = nnx.merge(graphdef, state)
    shared = _shared(network, crops, config.trainable)
    head_graph, trainable, frozen = nnx.split(network, _is_trainable(config.trainable), ...)
    finite = jnp.all(jnp.isfinite(keypoints), axis=-1)
    conf = jnp.where(finite & (keypoints[..., 2] > 0), keypoints[..., 2], 0.0)
    target = jnp.where(finite[..., None], keypoints[..., :2] / HALF - 1.0, 0.0)
    initial = _predict(network, shared, config.trainable)
    output = jax.vmap(_one, in_axes=(None, None, None, None, 0, 0, 0, None, None))(
        head_graph, trainable, frozen, model, shared, target, conf, rate, config)
    error = jax.vmap(_error_px, in_axes=(None, 0, 0, 0))
    return EFTResult(output, error(model, initial, target, conf), error(model, output, target, conf))


def fine_tune(graphdef: nnx.GraphDef, state: nnx.State, crops: Float[ArrayLike, "N H W 3"],
              keypoints: Float[ArrayLike, "N 25 3"], model: smplx_jax.BodyModel,
              config: EFTConfig = EFTConfig()) -> EFTResult:
    """EFT of the body regressor ``(graphdef, state)`` on each of N frames: ``crops`` normalised as the network
    takes them, ``keypoints`` BODY_25 ``x, y`` in crop pixels (0..224) and confidence (0 or NaN: missing)."""
    crops = jnp.asarray(crops, jnp.float32)
    keypoints = jnp.asarray(keypoints, jnp.float32)
    if crops.ndim != 4 or crops.shape[-1] != 3:
        raise ValueError(f"crops: expected (N, H, W, 3), got shape {crops.shape}")
    if keypoints.shape != (crops.shape[0], 25, 3):
        raise ValueError(f"keypoints: expected ({crops.shape[0]}, 25, 3) for {crops.shape[0]} crops, "
                         f"got shape {keypoints.shape}")
    # The learning rate is traced (changing it does not recompile).
    return _fine_tune(graphdef, state, crops, keypoints, model, jnp.float32(config.rate),
                      config=dataclasses.replace(config, learning_rate=None))
