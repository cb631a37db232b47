"""Typed training configs. Each module here (``hand``, ``body``, ``synthetic``, ``smoke``) has ``get_config()``
and a docstring with the command that runs it and the result it gave.

    python -m train.main --config synthetic --workdir runs/synthetic [--set batch_size=16 --set num_steps=100]
"""

import dataclasses
import importlib
import typing
from typing import Literal

NAMES = ("hand", "body", "synthetic", "smoke")


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    kind: Literal["hand", "body"]
    dataset: str  # a name of `train.datasets.open_dataset`
    data_dir: str = ""
    split: str = "train"
    eval_dataset: str = ""  # defaults to ``dataset``
    eval_split: str = "test"
    depth: int = 50  # ResNet depth (18, 34, 50)
    image_size: int = 224  # crop side; the networks pool globally, so any size runs
    start_wrist_rotvec: tuple[float, float, float] = (0.0, 0.0, 0.0)  # hand: the regressor's starting wrist
    batch_size: int = 64  # global, over all devices and hosts
    learning_rate: float = 1e-4  # Adam, as the paper
    warmup_steps: int = 0
    clip_norm: float = 100.0  # gradients clipped to this global norm
    num_steps: int = 100_000
    time_limit_s: float = 0.0  # stop (and checkpoint) after this much training time; 0 = no limit
    eval_every: int = 1000
    eval_examples: int = 1000
    log_every: int = 50
    checkpoint_every: int = 1000
    seed: int = 0
    workers: int = 2  # augmentation threads
    augment: bool = True

    def replace(self, **changes) -> "TrainConfig":
        return dataclasses.replace(self, **changes)


def get(name: str) -> TrainConfig:
    """The config of module ``train/configs/<name>.py``."""
    if name not in NAMES:
        raise ValueError(f"config: unknown {name!r}; known: {', '.join(NAMES)}")
    return importlib.import_module(f"train.configs.{name}").get_config()


def override(config: TrainConfig, assignments: list[str]) -> TrainConfig:
    """``["batch_size=16", "dataset=rhd"]`` applied, each value parsed as its field's type; a value that does not
    parse is a one-line `ValueError` naming the field and the type it expects."""
    fields = {f.name: f for f in dataclasses.fields(config)}
    hints = typing.get_type_hints(type(config))
    changes = {}
    for assignment in assignments:
        key, sep, value = assignment.partition("=")
        if not sep or key not in fields:
            raise ValueError(f"--set: expected FIELD=VALUE with FIELD one of {', '.join(fields)}, got {assignment!r}")
        changes[key] = _parse(key, hints[key], value)
    return config.replace(**changes)


_BOOLS = {"true": True, "1": True, "yes": True, "on": True, "false": False, "0": False, "no": False, "off": False}


def _parse(key: str, kind, value: str):
    """``value`` as type ``kind`` (a field's annotation), or `ValueError` naming ``key`` and the type expected."""
    def fail(expected: str):
        return ValueError(f"--set {key}={value}: {key} expects {expected}, got {value!r}")

    if typing.get_origin(kind) is Literal:
        choices = typing.get_args(kind)
        if value not in choices:
            raise fail("one of " + ", ".join(map(str, choices)))
        return value
    if kind is bool:
        if value.strip().lower() not in _BOOLS:
            raise fail("a boolean (true/false, 1/0, yes/no)")
        return _BOOLS[value.strip().lower()]
    if kind is int:
        try:
            return int(value)
        except ValueError:
            raise fail("an integer") from None
    if kind is float:
        try:
            return float(value)
        except ValueError:
            raise fail("a number") from None
    if typing.get_origin(kind) is tuple:
        items = typing.get_args(kind)
        parts = value.split(",")
        try:
            if len(parts) != len(items):
                raise ValueError
            return tuple(item(part) for item, part in zip(items, parts))
        except ValueError:
            raise fail(f"{len(items)} comma-separated numbers") from None
    if kind is str:
        return value
    raise fail(f"a {kind}")  # a field type this parser does not know
