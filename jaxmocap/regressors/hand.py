"""FrankMocap's hand regressor: ResNet features, an MLP, and a linear regressor iterated 3 times from a mean."""

import dataclasses

import jax
import jax.numpy as jnp
from flax import nnx
from jaxtyping import Array, Float

from jaxmocap.regressors.resnet import ResNet, feature_width

NUM_PARAMS = 61  # camera [s, tx, ty] (3) + wrist and 15 finger axis-angles (48) + betas (10)
CAMERA, POSE, BETAS = slice(0, 3), slice(3, 51), slice(51, 61)
ITERATIONS = 3


class Buffer(nnx.Variable):
    """A constant of the network stored with its weights (not trained)."""


@dataclasses.dataclass(frozen=True)
class HandConfig:
    """FrankMocap's hand regressor: the ResNet's depth and the regressor's hidden width."""

    depth: int = 50
    hidden: int = 1024


class HandRegressor(nnx.Module):
    """``(N, 224, 224, 3)`` normalised BGR crops of right hands -> ``(N, 61)`` raw FrankMocap parameters.

    Pose is axis-angle, finger joints in SMPL-X order and relative to SMPL-X's mean hand (see `decode`).
    ``dtype`` is the encoder's compute dtype (e.g. bfloat16); the heads always run in float32.
    """

    def __init__(self, config: HandConfig = HandConfig(), *, dtype=None, rngs: nnx.Rngs):
        self.config = config
        self.encoder = ResNet(config.depth, dtype=dtype, rngs=rngs)
        self.fc1 = nnx.Linear(feature_width(config.depth), config.hidden, rngs=rngs)
        self.feat_encoder = nnx.Linear(config.hidden, config.hidden, rngs=rngs)
        self.regressor = nnx.Linear(config.hidden + NUM_PARAMS, NUM_PARAMS, rngs=rngs)
        self.mean_params = Buffer(jnp.zeros(NUM_PARAMS))

    def __call__(self, images: Float[Array, "N H W 3"]) -> Float[Array, "N 61"]:
        feat = jax.nn.relu(self.fc1(self.encoder(images).astype(jnp.float32)))  # heads in float32
        feat = jax.nn.relu(self.feat_encoder(feat))  # feat_encoder = [ReLU, Linear, ReLU]; the first ReLU is a no-op
        params = jnp.broadcast_to(self.mean_params[...], (feat.shape[0], NUM_PARAMS))
        for _ in range(ITERATIONS):
            params = params + self.regressor(jnp.concatenate([feat, params], axis=-1))
        return params
