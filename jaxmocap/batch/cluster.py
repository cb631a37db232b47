"""Ray for a batch: started on this machine (127.0.0.1 only, no dashboard, no usage statistics) or joined at a
cluster's address. The only module of jaxmocap that imports Ray, an optional extra."""

import logging
import os
import signal

from jaxmocap.errors import InputError
from jaxmocap.signals import handling

LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1", "[::1]")


def on_this_machine(address: str | None) -> bool:
    """Whether ``address`` (None: a Ray of our own) keeps Ray on this machine."""
    return address is None or address.rsplit(":", 1)[0] in LOOPBACK_HOSTS


def import_ray():
    """The ``ray`` module, or `InputError` saying how to install it."""
    try:
        import ray
    except ImportError:
        raise InputError('batch needs Ray, an optional extra: pip install "jaxmocap[batch]"') from None
    return ray


def connect(address: str | None, workers: int | None):
    """``ray`` connected: without ``address`` a local Ray of ``workers`` CPUs (default: this machine's) that binds
    127.0.0.1 alone and starts no dashboard; else the cluster at ``address``. Usage statistics are off either way.
    Must run before Ray is first imported in the process (Ray reads the address switch at import)."""
    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    if on_this_machine(address):
        # Ray's switch for a single machine: the node's address is 127.0.0.1, and its servers bind that alone
        os.environ["RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER"] = "0"
    ray = import_ray()
    if on_this_machine(address) and ray._private.ray_constants.ENABLE_RAY_CLUSTER:
        raise RuntimeError("Ray was imported before jaxmocap could keep it on 127.0.0.1: run batch in a new process")
    quiet = dict(log_to_driver=False, logging_level=logging.ERROR)  # Ray's notes are not the batch's
    with handling(None, signal.SIGTERM):  # ray.init sets its own (exit at once); the command's stops a batch cleanly
        if address is None:
            ray.init(num_cpus=workers or os.cpu_count() or 1, include_dashboard=False, **quiet)
        else:
            try:
                ray.init(address=address, **quiet)
            except (ConnectionError, ValueError, RuntimeError) as err:
                raise InputError(f"--address {address}: cannot join a Ray cluster there ({err})") from None
    return ray
