"""Bucketed batches: padded to a few fixed sizes, chunked above the largest, unpadded on the way out."""

import jax
import jax.numpy as jnp
import numpy as np

from jaxmocap.buckets import bucket_size, map_in_buckets, pad_rows, padded_size

BUCKETS = (1, 4, 16)


def test_sizes():
    assert [bucket_size(n, BUCKETS) for n in (1, 2, 4, 5, 16, 17)] == [1, 4, 4, 16, 16, 16]
    assert [padded_size(n, BUCKETS) for n in (3, 16, 17, 33)] == [4, 16, 32, 48]
    np.testing.assert_array_equal(pad_rows(np.array([7, 8]), 4), [7, 8, 7, 7])
    assert isinstance(pad_rows(jnp.ones((1, 2)), 4), jax.Array)


def test_map_in_buckets_sees_only_bucket_sizes_and_returns_the_real_rows():
    seen = []

    def double(chunk, n):
        seen.append((len(chunk["x"]), n))
        return {"y": 2 * chunk["x"], "z": chunk["x"][:, 0] + chunk["w"]}

    x, w = np.arange(37 * 2.0).reshape(37, 2), np.arange(37.0)
    out = map_in_buckets(double, {"x": jnp.asarray(x), "w": w}, BUCKETS)
    assert seen == [(16, 16), (16, 16), (16, 5)]
    np.testing.assert_array_equal(out["y"], 2 * x)
    np.testing.assert_array_equal(out["z"], x[:, 0] + w)
    numpy_out = map_in_buckets(lambda chunk, n: 2 * chunk, x, BUCKETS)  # NumPy in, NumPy out: no programs run
    assert type(numpy_out) is np.ndarray and np.array_equal(numpy_out, 2 * x)
