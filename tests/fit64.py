"""Float64 problems of one synthetic frame, shared by the fit's test files (with the ``x64`` fixture)."""

import jax
import jax.numpy as jnp

import smplx_jax
from jaxmocap.integrate import synthetic


def load64(model_dir):
    return smplx_jax.load_model(model_dir / "smplx" / "SMPLX_NEUTRAL.npz", dtype=jnp.float64)


def synthetic64(model, **kwargs):
    """A one-frame synthetic problem in float64: keypoints (67, 3) and the start."""
    data = synthetic.make_problem(model, 1, **kwargs)
    return jnp.asarray(data.keypoints[0], jnp.float64), jax.tree.map(lambda a: jnp.asarray(a[0], jnp.float64),
                                                                      data.init)
