"""`pytree_dataclass`: a frozen dataclass as a pytree that JAX rebuilds without calling ``__init__``."""

import dataclasses
import operator
import typing

import jax


def pytree_dataclass(cls):
    """Register a dataclass as a pytree: fields with ``metadata=dict(static=True)`` are static (hashable, part of
    the tree structure), the others are children.

    Unlike ``jax.tree_util.register_dataclass``, unflattening does not call ``__init__``: JAX and the libraries on
    it rebuild trees with leaves that are not arrays (``tree_map`` to booleans, sentinels, shape structs), which
    a checked ``__init__`` (the tests check the fields' annotations) would refuse.
    """
    fields = dataclasses.fields(cls)
    data = tuple(f.name for f in fields if not f.metadata.get("static", False))
    meta = tuple(f.name for f in fields if f.metadata.get("static", False))
    keys = tuple(jax.tree_util.GetAttrKey(name) for name in data)
    get_data, get_meta = _attributes(data), _attributes(meta)

    @typing.no_type_check
    def flatten(x):
        return get_data(x), get_meta(x)

    @typing.no_type_check
    def flatten_with_keys(x):
        return tuple(zip(keys, get_data(x))), get_meta(x)

    @typing.no_type_check
    def unflatten(aux, children):
        x = object.__new__(cls)
        for name, value in zip(data, children):
            object.__setattr__(x, name, value)
        for name, value in zip(meta, aux):
            object.__setattr__(x, name, value)
        return x

    jax.tree_util.register_pytree_with_keys(cls, flatten_with_keys, unflatten, flatten)
    return cls


def _attributes(names: tuple[str, ...]):
    """A function of ``x`` giving the tuple of its attributes ``names`` (with C's `operator.attrgetter` where it
    gives a tuple: jit flattens its arguments at every call)."""
    if len(names) >= 2:
        return operator.attrgetter(*names)
    return lambda x: tuple(getattr(x, name) for name in names)
