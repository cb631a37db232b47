"""`BatchConfig`: every option of a batch, built by ``jaxmocap batch``."""

from dataclasses import dataclass

from jaxmocap.errors import InputError
from jaxmocap.pipeline.config import RunConfig


@dataclass(frozen=True)
class BatchConfig:
    """``jaxmocap batch INPUT... --out DIR [--workers N] [--address ADDR] [run's options]`` as one value:
    ``batch(BatchConfig(inputs, RunConfig("", ...)), out_dir)``.

    ``inputs``: video files, image folders or stream URLs. ``run``: the options every video runs with (its
    ``source`` is ignored; its ``progress`` is the batch's bar over the videos, each video runs without bars).
    ``workers``: videos solved at once (default: a local Ray's cores, or all the cluster takes). ``address``: a Ray
    cluster's ``HOST:PORT``; without it a local Ray on 127.0.0.1, for this batch alone. ``retries``: how often a
    video whose worker died (killed, out of memory, its machine lost) is tried again.
    """

    inputs: tuple[str, ...]
    run: RunConfig
    workers: int | None = None
    address: str | None = None
    retries: int = 3

    def __post_init__(self):
        if not self.inputs:
            raise InputError("no inputs: name videos, image folders or stream URLs, or a --manifest")
        if self.workers is not None and self.workers < 1:
            raise InputError(f"--workers must be positive, got {self.workers}")
        if self.retries < 0:
            raise InputError(f"retries must be 0 or more, got {self.retries}")
        if any(str(i).isdigit() for i in self.inputs):
            raise InputError("a batch takes no webcam (a webcam never ends): use jaxmocap run or live")
        object.__setattr__(self, "inputs", tuple(str(i) for i in self.inputs))
