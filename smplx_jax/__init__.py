"""smplx_jax: a pure-function SMPL-X body model in JAX.

    model = smplx_jax.load_model(smplx_jax.default_model_path())
    out = smplx_jax.forward(model, smplx_jax.SMPLXParams.zeros())   # one body; batch with jax.vmap
"""

from smplx_jax import constants, rotations
from smplx_jax.default_model import default_model_path, model_path, write_default_model
from smplx_jax.forward import Output, Skeleton, forward, forward_joints, posed_skeleton
from smplx_jax.hand import HandModel, HandOutput, hand_forward, hand_model
from smplx_jax.model import BodyModel, load_model
from smplx_jax.model_file import ModelFileError, ModelNotFoundError
from smplx_jax.params import (
    SIDES,
    SMPLXParams,
    hand_pose_from_pca,
    hand_pose_from_relative,
    hand_pose_to_pca,
    hand_pose_to_relative,
)

__all__ = [
    "SIDES", "BodyModel", "HandModel", "HandOutput", "ModelFileError", "ModelNotFoundError", "Output", "SMPLXParams",
    "Skeleton", "constants", "default_model_path", "forward", "forward_joints", "hand_forward", "hand_model",
    "hand_pose_from_pca", "hand_pose_from_relative", "hand_pose_to_pca", "hand_pose_to_relative", "load_model",
    "model_path", "posed_skeleton", "rotations", "write_default_model",
]
