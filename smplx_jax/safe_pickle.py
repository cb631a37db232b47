"""Unpickling that runs no code from the file: numpy arrays and plain containers, nothing callable beyond them.

Every name a pickle refers to is looked up in an exact allow-list before anything is called; a name outside it
raises `RefusedPickle`. The allowed callables are numpy's own array, scalar and dtype rebuilders, a latin-1-only
``_codecs.encode`` (arrays pickled under protocol 2) and a ``copyreg._reconstructor`` that only builds the inert
stand-ins a caller names (chumpy and scipy objects in model files).
"""

import copyreg
import pickle
from collections.abc import Callable
from typing import BinaryIO

import numpy as np

StandIn = Callable[[str, str], type | None]


class RefusedPickle(pickle.UnpicklingError):
    """The pickle refers to ``reference`` (``module.name``), which the allow-list does not hold; nothing the file
    names has been called."""

    def __init__(self, reference: str):
        super().__init__(f"refers to {reference}")
        self.reference = reference


def load(file: BinaryIO, stand_in: StandIn | None = None) -> object:
    """The object pickled in ``file`` (Python 2 pickles read as latin-1). ``stand_in(module, name)`` may give an
    inert class (built with ``object.__new__``, its state set by its own ``__setstate__``) for a class the file
    names; any other name outside the allow-list raises `RefusedPickle` before it is called."""
    return _Unpickler(file, stand_in).load()


def _latin1_encode(text: str, encoding: str) -> bytes:
    """``_codecs.encode`` as protocol-2 pickles of bytes use it, and nothing else."""
    if encoding not in ("latin1", "latin-1") or not isinstance(text, str):
        raise RefusedPickle(f"_codecs.encode(..., {encoding!r})")
    return text.encode("latin1")


def _array_names() -> dict[tuple[str, str], object]:
    """numpy's rebuilders under the module names numpy 1.x (``numpy.core``) and 2.x (``numpy._core``) write."""
    rebuilders = {"_reconstruct": np.arange(1.0).__reduce__()[0], "scalar": np.float64(1).__reduce__()[0],
                  "_frombuffer": np.arange(1.0).__reduce_ex__(5)[0]}
    modules = {"_reconstruct": "multiarray", "scalar": "multiarray", "_frombuffer": "numeric"}
    names = {(f"numpy.{core}.{modules[name]}", name): value
             for name, value in rebuilders.items() for core in ("core", "_core")}
    return names | {("numpy", "ndarray"): np.ndarray, ("numpy", "dtype"): np.dtype,
                    ("_codecs", "encode"): _latin1_encode, ("__builtin__", "object"): object,
                    ("builtins", "object"): object}


_ALLOWED = _array_names()


class _Unpickler(pickle.Unpickler):
    def __init__(self, file: BinaryIO, stand_in: StandIn | None):
        super().__init__(file, encoding="latin1")
        self._stand_in = stand_in or (lambda module, name: None)
        self._stand_ins: set[type] = set()

    def find_class(self, module: str, name: str):
        if (module, name) in _ALLOWED:
            return _ALLOWED[module, name]
        if (module, name) in (("copy_reg", "_reconstructor"), ("copyreg", "_reconstructor")):
            return self._reconstructor
        stand_in = self._stand_in(module, name)
        if stand_in is None:
            raise RefusedPickle(f"{module}.{name}")
        self._stand_ins.add(stand_in)
        return stand_in

    def _reconstructor(self, cls, base, state):
        """``copyreg._reconstructor`` for the stand-ins only (as Python 2 pickled new-style objects)."""
        if cls not in self._stand_ins or base is not object or state is not None:
            raise RefusedPickle(f"copyreg._reconstructor({getattr(cls, '__name__', cls)!s}, ...)")
        return copyreg._reconstructor(cls, object, None)
