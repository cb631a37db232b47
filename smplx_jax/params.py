"""`SMPLXParams`: the parameters of one body, and conversions of hand poses (mean-relative, PCA)."""

import dataclasses
from typing import Literal

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from smplx_jax.pytree import pytree_dataclass

Side = Literal["left", "right"]
SIDES: tuple[Side, Side] = ("left", "right")  # in the order of every pair of per-side arrays


@pytree_dataclass
@dataclasses.dataclass(frozen=True)
class SMPLXParams:
    """One body, axis-angle, or a batch of bodies (the same leading axes on every field: `forward` takes one, so
    batches go through ``jax.vmap``), as JAX or numpy arrays. Hand poses are absolute (``flat_hand_mean=True`` in
    the ``smplx`` package)."""

    global_orient: Float[ArrayLike, "*batch 3"]
    body_pose: Float[ArrayLike, "*batch 21 3"]
    left_hand_pose: Float[ArrayLike, "*batch 15 3"]
    right_hand_pose: Float[ArrayLike, "*batch 15 3"]
    jaw_pose: Float[ArrayLike, "*batch 3"]
    leye_pose: Float[ArrayLike, "*batch 3"]
    reye_pose: Float[ArrayLike, "*batch 3"]
    betas: Float[ArrayLike, "*batch num_betas"]
    expression: Float[ArrayLike, "*batch num_expression"]
    transl: Float[ArrayLike, "*batch 3"]

    @classmethod
    def zeros(cls, num_betas: int = 10, num_expression: int = 10, dtype=jnp.float32) -> "SMPLXParams":
        """The rest pose with mean shape (flat hands)."""
        def z(*shape):
            return jnp.zeros(shape, dtype)
        return cls(z(3), z(21, 3), z(15, 3), z(15, 3), z(3), z(3), z(3), z(num_betas), z(num_expression), z(3))

    def replace(self, **changes) -> "SMPLXParams":
        return dataclasses.replace(self, **changes)

    def full_pose(self) -> Float[Array, "55 3"]:
        """Axis-angle of all 55 joints in SMPL-X order."""
        return jnp.concatenate([
            self.global_orient[None], self.body_pose, self.jaw_pose[None], self.leye_pose[None],
            self.reye_pose[None], self.left_hand_pose, self.right_hand_pose,
        ])

    def shape_components(self) -> Float[Array, "S"]:
        return jnp.concatenate([self.betas, self.expression])


def hand_pose_from_relative(model, relative_pose: Float[ArrayLike, "*batch 15 3"], side: Side
                            ) -> Float[Array, "*batch 15 3"]:
    """Absolute hand pose from one relative to the model's mean hand (``flat_hand_mean=False``)."""
    return relative_pose + model.hand_mean[SIDES.index(side)].reshape(15, 3)


def hand_pose_to_relative(model, hand_pose: Float[ArrayLike, "*batch 15 3"], side: Side
                          ) -> Float[Array, "*batch 15 3"]:
    """The hand pose relative to the model's mean hand."""
    return hand_pose - model.hand_mean[SIDES.index(side)].reshape(15, 3)


def hand_pose_from_pca(model, pca_coeffs: Float[Array, "n"], side: Side) -> Float[Array, "15 3"]:
    """Absolute hand pose ``mean + coeffs @ components[:n]``, as the ``smplx`` package computes it with
    ``use_pca=True, flat_hand_mean=False``. Its ``flat_hand_mean=True`` variant (no mean) is
    `hand_pose_to_relative` of this."""
    components = model.hand_components[SIDES.index(side), : pca_coeffs.shape[0]]
    return hand_pose_from_relative(model, (pca_coeffs @ components).reshape(15, 3), side)


def hand_pose_to_pca(model, hand_pose: Float[Array, "15 3"], side: Side, num_coeffs: int) -> Float[Array, "n"]:
    """Least-squares PCA coefficients of an absolute hand pose (exact when the pose lies in the span)."""
    components = model.hand_components[SIDES.index(side), :num_coeffs]
    relative = hand_pose_to_relative(model, hand_pose, side).reshape(45)
    return jnp.linalg.lstsq(components.T, relative)[0]
