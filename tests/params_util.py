"""Random SMPL-X parameters for tests: batches of poses with large rotations, and their torch form."""

import jax.numpy as jnp
import numpy as np

import smplx_jax


def random_rotvecs(rng, shape, max_angle=3.5):
    """Uniform random axes; angles uniform in [0, max_angle] (past pi), some exactly zero."""
    axes = rng.normal(size=shape + (3,))
    axes /= np.linalg.norm(axes, axis=-1, keepdims=True)
    angles = rng.uniform(0, max_angle, shape + (1,))
    angles[rng.uniform(size=shape + (1,)) < 0.05] = 0.0
    return axes * angles


def random_params(seed, batch, num_betas=10, num_expression=10, max_angle=3.5) -> smplx_jax.SMPLXParams:
    """A batch (leading axis) of random bodies."""
    rng = np.random.default_rng(seed)
    def f(a):
        return jnp.asarray(a, jnp.float32)
    return smplx_jax.SMPLXParams(
        global_orient=f(random_rotvecs(rng, (batch,), max_angle)),
        body_pose=f(random_rotvecs(rng, (batch, 21), max_angle)),
        left_hand_pose=f(random_rotvecs(rng, (batch, 15), max_angle)),
        right_hand_pose=f(random_rotvecs(rng, (batch, 15), max_angle)),
        jaw_pose=f(random_rotvecs(rng, (batch,), max_angle)),
        leye_pose=f(random_rotvecs(rng, (batch,), max_angle)),
        reye_pose=f(random_rotvecs(rng, (batch,), max_angle)),
        betas=f(rng.normal(0, 1.5, (batch, num_betas))),
        expression=f(rng.normal(0, 1.5, (batch, num_expression))),
        transl=f(rng.normal(0, 1.0, (batch, 3))),
    )


def torch_inputs(params: smplx_jax.SMPLXParams, **hands) -> dict:
    """Keyword arguments for a batched ``smplx.SMPLX`` forward; ``hands`` override the hand poses."""
    import torch

    batch = params.betas.shape[0]
    def t(a):
        return torch.tensor(np.asarray(a), dtype=torch.float32).reshape(batch, -1)
    names = ("global_orient", "body_pose", "left_hand_pose", "right_hand_pose", "jaw_pose", "leye_pose",
             "reye_pose", "betas", "expression", "transl")
    kwargs = {name: t(getattr(params, name)) for name in names}
    kwargs.update({name: t(value) for name, value in hands.items()})
    return kwargs
