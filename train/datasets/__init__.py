"""Dataset adapters: each reads one dataset's real on-disk layout into `HandSample`s or `BodySample`s.

    samples = train.datasets.open_dataset("freihand", "/data/FreiHAND", "train")   # lazy: images load on access
"""

import importlib
from collections.abc import Sequence
from pathlib import Path

from train.datasets.sample import BodyExample, BodySample, HandExample, HandSample

# name -> (module, function, kind)
_READERS = {
    "freihand": ("freihand", "read", "hand"),
    "ho3d": ("ho3d", "read", "hand"),
    "rhd": ("rhd", "read", "hand"),
    "stb": ("stb", "read", "hand"),
    "mpii_nzsl": ("mpii_nzsl", "read", "hand"),
    "synthetic_hands": ("synthetic", "read_hands", "hand"),
    "coco_eft": ("eft", "read_coco", "body"),
    "mpii_eft": ("eft", "read_mpii", "body"),
    "h36m": ("h36m", "read", "body"),
    "synthetic_bodies": ("synthetic", "read_bodies", "body"),
}
HAND_DATASETS = tuple(name for name, (_, _, kind) in _READERS.items() if kind == "hand")
BODY_DATASETS = tuple(name for name, (_, _, kind) in _READERS.items() if kind == "body")


def dataset_kind(name: str) -> str:
    """"hand" or "body"."""
    _check(name)
    return _READERS[name][2]


def open_dataset(name: str, root: str | Path, split: str) -> Sequence[HandSample] | Sequence[BodySample]:
    """The samples of ``split`` ("train", "test", ...) of dataset ``name`` stored under ``root``."""
    _check(name)
    module, function, _ = _READERS[name]
    reader = getattr(importlib.import_module(f"train.datasets.{module}"), function)
    return reader(Path(root), split)


def _check(name: str) -> None:
    if name not in _READERS:
        raise ValueError(f"dataset: unknown {name!r}; known: {', '.join(_READERS)}")


__all__ = ["BODY_DATASETS", "BodyExample", "BodySample", "HAND_DATASETS", "HandExample", "HandSample",
           "dataset_kind", "open_dataset"]
