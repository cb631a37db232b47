"""Spreading a batch of frames over all JAX devices (GPUs, or CPU devices) along its leading axis."""

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec


def frame_sharding(num_frames: int) -> NamedSharding | None:
    """Split a leading axis of ``num_frames`` over all devices; None with one device or when it does not divide."""
    devices = jax.devices()
    if len(devices) == 1 or num_frames % len(devices):
        return None
    return NamedSharding(Mesh(np.array(devices), ("frames",)), PartitionSpec("frames"))


def shard_frames(tree, num_frames: int):
    """The arrays of ``tree`` (each with ``num_frames`` leading) placed across devices; jitted functions of them
    then run partitioned over the frames, and give the same numbers as on one device."""
    sharding = frame_sharding(num_frames)
    return tree if sharding is None else jax.device_put(tree, sharding)
