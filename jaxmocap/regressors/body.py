"""SPIN's HMR body regressor as FrankMocap ships it: ResNet features and iterative error feedback (3 steps)."""

import dataclasses
from typing import NamedTuple

import jax.numpy as jnp
from flax import nnx
from jaxtyping import Array, Float

from jaxmocap.regressors.hand import Buffer
from jaxmocap.regressors.resnet import ResNet, feature_width
from smplx_jax.rotations import rot6d_to_rotmat

NUM_JOINTS = 24  # SMPL
ITERATIONS = 3


@dataclasses.dataclass(frozen=True)
class BodyConfig:
    """FrankMocap's body regressor: the ResNet's depth, the regressor's hidden width, the betas it predicts."""

    depth: int = 50
    hidden: int = 1024
    num_betas: int = 10


class BodyOutput(NamedTuple):
    """The body regressor's prediction for N crops: SMPL joint rotations, shape and crop camera."""

    rotmats: Float[Array, "N 24 3 3"]  # SMPL joints; 0 is the global orientation (camera frame, y down)
    betas: Float[Array, "N 10"]
    camera: Float[Array, "N 3"]  # weak perspective [s, tx, ty] in the normalised crop


class BodyRegressor(nnx.Module):
    """``(N, 224, 224, 3)`` ImageNet-normalised RGB crops -> SMPL rotations (from 6D), betas and camera.

    fc1 -> Dropout -> fc2 -> Dropout -> decpose/decshape/deccam; the dropouts are identities at inference and
    are left out. ``dtype`` is the encoder's compute dtype (e.g. bfloat16); the heads always run in float32.
    """

    def __init__(self, config: BodyConfig = BodyConfig(), *, dtype=None, rngs: nnx.Rngs):
        self.config = config
        width, pose = feature_width(config.depth), NUM_JOINTS * 6
        self.encoder = ResNet(config.depth, dtype=dtype, rngs=rngs)
        self.fc1 = nnx.Linear(width + pose + config.num_betas + 3, config.hidden, rngs=rngs)
        self.fc2 = nnx.Linear(config.hidden, config.hidden, rngs=rngs)
        self.decpose = nnx.Linear(config.hidden, pose, rngs=rngs)
        self.decshape = nnx.Linear(config.hidden, config.num_betas, rngs=rngs)
        self.deccam = nnx.Linear(config.hidden, 3, rngs=rngs)
        self.init_pose = Buffer(jnp.zeros(pose))
        self.init_shape = Buffer(jnp.zeros(config.num_betas))
        self.init_cam = Buffer(jnp.zeros(3))

    def __call__(self, images: Float[Array, "N H W 3"]) -> BodyOutput:
        return self.regress(self.encoder(images))

    def regress(self, features: Float[Array, "N F"]) -> BodyOutput:
        """The heads on the encoder's pooled features."""
        feat = features.astype(jnp.float32)  # heads in float32
        n = feat.shape[0]
        start = (self.init_pose, self.init_shape, self.init_cam)
        pose, shape, cam = (jnp.broadcast_to(b[...], (n, b.shape[0])) for b in start)
        for _ in range(ITERATIONS):
            x = self.fc2(self.fc1(jnp.concatenate([feat, pose, shape, cam], axis=-1)))
            pose, shape, cam = pose + self.decpose(x), shape + self.decshape(x), cam + self.deccam(x)
        return BodyOutput(rot6d_to_rotmat(pose.reshape(n, NUM_JOINTS, 6)), shape, cam)
