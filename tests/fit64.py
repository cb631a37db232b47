"""Float64 problems of one synthetic frame, shared by the fit's test files (with the ``x64`` fixture), and the jit
of the tests' own programs that compile long and run a few times."""

import functools

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


# The fit's gradients and Jacobians that the tests check compile for 10-40 s each and then run a handful of times:
# LLVM at -O0 (XLA's own passes as ever, IEEE arithmetic as ever) compiles them in about half the time and runs
# them slower, which these few runs do not feel (docs/BENCHMARKS.md, "Tests that share their programs").
jit_fast_compile = functools.partial(jax.jit, compiler_options={"xla_backend_optimization_level": 0})
