"""Batches of examples for training: shuffled per epoch, the last incomplete batch dropped, and a pure function of
(seed, step), so a run resumed at step ``k`` sees exactly the batches it would have seen. Examples are made in a
thread pool (OpenCV releases the GIL) and come out in order.
"""

import collections
import itertools
from collections.abc import Iterator, Sequence
from concurrent.futures import Executor, ThreadPoolExecutor

import numpy as np

from train.augment import AugmentConfig, example
from train.datasets.sample import BodyExample, BodySample, HandExample, HandSample

Sample = HandSample | BodySample
Example = HandExample | BodyExample


def stack(examples: Sequence[Example]) -> Example:
    """Examples of one type -> one of that type with a leading batch axis."""
    if not examples or len({type(e) for e in examples}) != 1:
        raise ValueError(f"examples: expected a non-empty sequence of one example type, got "
                         f"{sorted({type(e).__name__ for e in examples})}")
    return type(examples[0])(*(np.stack(field) for field in zip(*examples)))


def batch_indices(num_samples: int, batch_size: int, step: int, seed: int) -> tuple[int, np.ndarray]:
    """The epoch of ``step`` and the dataset indices of its batch (epochs are ``num_samples // batch_size``
    steps, each a fresh permutation)."""
    if not 0 < batch_size <= num_samples:
        raise ValueError(f"batch_size: expected 1..{num_samples} (the dataset size), got {batch_size}")
    if step < 0:
        raise ValueError(f"step: expected >= 0, got {step}")
    epoch, position = divmod(step, num_samples // batch_size)
    order = np.random.default_rng([seed, 0, epoch, 0]).permutation(num_samples)
    return epoch, order[position * batch_size:(position + 1) * batch_size]


def _jobs(dataset, batch_size, step, size, seed, augment, config, shard=(0, 1)):
    epoch, indices = batch_indices(len(dataset), batch_size, step, seed)
    part, parts = shard
    for index in np.array_split(indices, parts)[part]:
        rng = np.random.default_rng([seed, 1, epoch, int(index)]) if augment else None
        yield dataset[int(index)], size, rng, config


def batch_at(dataset: Sequence[Sample], step: int, batch_size: int, size: int, *, seed: int, augment: bool = True,
             config: AugmentConfig | None = None, executor: Executor | None = None) -> Example:
    """The batch of training step ``step`` (``config`` None: the sample type's default augmentation)."""
    jobs = list(_jobs(dataset, batch_size, step, size, seed, augment, config))
    made = executor.map(lambda job: example(*job), jobs) if executor else (example(*job) for job in jobs)
    return stack(list(made))


def batches(dataset: Sequence[Sample], batch_size: int, size: int, *, seed: int, start_step: int = 0,
            augment: bool = True, workers: int = 2, config: AugmentConfig | None = None,
            prefetch: int = 2, shard: tuple[int, int] = (0, 1)) -> Iterator[Example]:
    """``batch_at`` for steps ``start_step, start_step + 1, ...`` (endless), ``prefetch`` batches made ahead by
    ``workers`` threads. ``shard = (i, n)``: only part ``i`` of ``n`` of each batch (host ``i`` of ``n``)."""
    if workers < 1 or prefetch < 1:
        raise ValueError(f"workers and prefetch: expected >= 1, got {workers}, {prefetch}")
    if batch_size % shard[1] or not 0 <= shard[0] < shard[1]:
        raise ValueError(f"shard: expected (i, n) with 0 <= i < n and n dividing {batch_size}, got {shard}")
    batch_indices(len(dataset), batch_size, start_step, seed)  # validates before any thread starts
    pool = ThreadPoolExecutor(workers)
    pending = collections.deque()
    try:
        for step in itertools.count(start_step):
            jobs = _jobs(dataset, batch_size, step, size, seed, augment, config, shard)
            pending.append([pool.submit(example, *job) for job in jobs])
            if len(pending) > prefetch:
                yield stack([future.result() for future in pending.popleft()])
    finally:  # the consumer stopped: drop the work made ahead
        pool.shutdown(wait=False, cancel_futures=True)
