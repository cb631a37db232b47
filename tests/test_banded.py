"""`jaxmocap.integrate.banded`: block-banded systems of a time series against dense linear algebra."""

import jax.numpy as jnp
import numpy as np

from jaxmocap.integrate import banded


def random_banded(rng, frames: int, m: int) -> banded.Banded:
    """A symmetric positive definite block-banded matrix (bandwidth 2): ``J^T J`` of a random banded ``J``."""
    rows = rng.normal(size=(frames, 3, 2 * m, m))  # each frame's residuals on itself and the next two frames
    dense = np.zeros((frames * m, frames * m))
    for t in range(frames):
        for i in range(3):
            for j in range(3):
                if t + i < frames and t + j < frames:
                    dense[(t + i) * m:(t + i + 1) * m, (t + j) * m:(t + j + 1) * m] += rows[t, i].T @ rows[t, j]
    blocks = dense.reshape(frames, m, frames, m)
    pick = [np.stack([blocks[min(t + k, frames - 1), :, t] * (t + k < frames) for t in range(frames)])
            for k in range(3)]
    return banded.Banded(*(jnp.asarray(p, jnp.float32) for p in pick)), dense


def test_factor_and_solve_match_dense_solves():
    rng = np.random.default_rng(0)
    systems = [random_banded(rng, 7, m) for m in (4, 2)]
    np.testing.assert_allclose(np.asarray(systems[0][0].dense()), systems[0][1], rtol=1e-5, atol=1e-4)
    g = [rng.normal(size=(7, m)) for m in (4, 2)]
    solved = banded.solve(banded.factor([a for a, _ in systems]), [jnp.asarray(gi, jnp.float32) for gi in g])
    for (_, dense), gi, x in zip(systems, g, solved):
        expected = np.linalg.solve(dense, gi.reshape(-1)).reshape(gi.shape)
        np.testing.assert_allclose(np.asarray(x), expected, rtol=1e-3, atol=1e-4 * np.abs(expected).max())
