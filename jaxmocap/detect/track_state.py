"""The trackers' results (`pose.PoseResult`, `hands.HandResult`: named tuples of arrays, floats and `roi.Rect`s) as
flat float64 arrays and back, for their ``state``/``restore`` (a resumed run tracks as an uninterrupted one)."""

import numpy as np

from .roi import Rect


def results_state(prefix: str, cls, results: list, empty=None) -> dict[str, np.ndarray]:
    """``{f"{prefix}_{field}": (N, ...) float64}`` for each field of ``cls`` over ``results`` (a None result is
    written as ``empty``); ``(0,)`` arrays when there are none."""
    out = {}
    for name in cls._fields:
        values = [np.asarray(getattr(r if r is not None else empty, name), np.float64) for r in results]
        out[f"{prefix}_{name}"] = np.asarray(values) if values else np.zeros((0,))
    return out


def result_of(state: dict[str, np.ndarray], prefix: str, cls, i: int):
    """The ``i``-th ``cls`` written by `results_state`: its rects as `Rect`, scalars as floats."""
    fields = {name: state[f"{prefix}_{name}"][i] for name in cls._fields}
    return cls(**{name: Rect(*map(float, v)) if name.endswith("roi") else v if v.ndim else float(v)
                  for name, v in fields.items()})
