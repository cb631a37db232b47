"""Fixed batch sizes ("buckets") for jitted functions: a batch is padded to the next bucket by repeating its first
row, and a larger one runs in chunks of the largest bucket, so any number of rows reuses a few compiled shapes."""

import jax
import jax.numpy as jnp
import numpy as np


def bucket_size(n: int, buckets: tuple[int, ...]) -> int:
    """The smallest of the ascending ``buckets`` that holds ``n`` rows; the largest when none does."""
    return next((b for b in buckets if b >= n), buckets[-1])


def padded_size(n: int, buckets: tuple[int, ...]) -> int:
    """The rows ``n`` rows are padded to when they feed one jitted call whole: their bucket, or above the largest
    bucket a multiple of it (the whole chunks `map_in_buckets` cuts)."""
    return bucket_size(n, buckets) if n <= buckets[-1] else -(-n // buckets[-1]) * buckets[-1]


def pad_rows(a, size: int):
    """A NumPy or JAX array with its first row repeated to ``size`` rows."""
    if size == len(a):
        return a
    xp = jnp if isinstance(a, jax.Array) else np
    return xp.concatenate([a, xp.repeat(a[:1], size - len(a), axis=0)])


def map_in_buckets(fn, tree, buckets: tuple[int, ...]):
    """``fn(chunk, n)`` over the leading axis of the arrays of ``tree`` (at least one row): in chunks of at most the
    largest bucket, each padded by `pad_rows` to its `bucket_size` (its first ``n`` rows are real); returns the
    real rows of the outputs, concatenated (NumPy outputs stay NumPy)."""
    total = len(jax.tree.leaves(tree)[0])
    outs = []
    for start in range(0, total, buckets[-1]):
        n = min(buckets[-1], total - start)
        # (slicing or padding a JAX array runs a program: none where the rows are whole)
        chunk = jax.tree.map(lambda a: pad_rows(a if n == total else a[start:start + n], bucket_size(n, buckets)), tree)
        outs.append(jax.tree.map(lambda a: a if n == len(a) else a[:n], fn(chunk, n)))
    return outs[0] if len(outs) == 1 else jax.tree.map(
        lambda *parts: (jnp if isinstance(parts[0], jax.Array) else np).concatenate(parts), *outs)
