"""Our weights format: ``DIR/regressors.json`` (architecture, files, checksums) beside ``hand.npz`` and
``body.npz`` (one array per variable, named like the PyTorch checkpoints, read with ``allow_pickle=False``)."""

import dataclasses
import functools
import json
import zipfile
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx

from jaxmocap.errors import InputError
from jaxmocap.regressors.body import BodyConfig, BodyRegressor
from jaxmocap.regressors.hand import HandConfig, HandRegressor
from jaxmocap.result_files import file_sha256
from jaxmocap.xla_options import RUN_ONCE
from smplx_jax.atomic_files import atomic_path, atomic_write_text

FORMAT, VERSION, INDEX = "jaxmocap-regressors", 1, "regressors.json"
_KINDS = {"hand": (HandRegressor, HandConfig), "body": (BodyRegressor, BodyConfig)}


class WeightsError(InputError):
    """A checkpoint or weights folder that is missing, corrupt, or not the expected network."""


class Regressors(NamedTuple):
    """FrankMocap's two networks, as `load` gives them."""

    hand: HandRegressor
    body: BodyRegressor


def initialised(new: Callable[[], nnx.Module]) -> nnx.Module:
    """``new()``, a network with fresh random weights, its initialisers compiled as one program with LLVM at -O0:
    they run once, so compiling is all they cost (a ResNet-18 built so in 4.8 s rather than 11.6 s on 2 CPU cores:
    docs/BENCHMARKS.md). The weights are ``new()``'s, rounding aside."""
    graphdef, _ = nnx.split(nnx.eval_shape(new))
    state = jax.jit(lambda: nnx.split(new())[1], compiler_options=RUN_ONCE)()
    return nnx.merge(graphdef, state)


def variable_names(module: nnx.Module) -> dict[str, tuple[int, ...]]:
    """``{"encoder.layer1.0.conv1.kernel": shape, ...}``: every variable of a network (abstract is fine)."""
    _, state = nnx.split(module)
    return {".".join(map(str, path)): tuple(v.shape) for path, v in nnx.to_flat_state(state)}


def build(kind: str, config, arrays: dict[str, np.ndarray], source: str, *, dtype=None) -> nnx.Module:
    """A network of ``kind`` ("hand"/"body") with exactly these arrays; `WeightsError` names what is off."""
    graphdef, flat = _abstract(kind, config, dtype)
    expected = {".".join(map(str, path)): tuple(v.shape) for path, v in flat}
    missing, unexpected = sorted(set(expected) - set(arrays)), sorted(set(arrays) - set(expected))
    if missing or unexpected:
        raise WeightsError(f"{source}: not the {kind} network: "
                           + "; ".join(f"{what} {_few(keys)}" for what, keys in
                                       (("missing", missing), ("unexpected", unexpected)) if keys))
    for name, shape in expected.items():
        if tuple(arrays[name].shape) != shape:
            raise WeightsError(f"{source}: {kind} variable {name} has shape {tuple(arrays[name].shape)}, "
                               f"expected {shape}")
    leaves = [(path, v.replace(jnp.asarray(arrays[".".join(map(str, path))], jnp.float32))) for path, v in flat]
    return nnx.merge(graphdef, nnx.from_flat_state(leaves))


@functools.lru_cache(maxsize=8)
def _abstract(kind: str, config, dtype) -> tuple:
    """The network's graph definition and its variables' shapes (an `nnx.FlatState`), traced once per architecture
    and dtype (a second for a ResNet-50); `build` puts new variables in, leaving these as they are."""
    cls, _ = _KINDS[kind]
    graphdef, state = nnx.split(nnx.eval_shape(lambda: cls(config, dtype=dtype, rngs=nnx.Rngs(0))))
    return graphdef, nnx.to_flat_state(state)


def save(out_dir: Path, networks: Regressors | dict[str, nnx.Module], sources: dict[str, str]) -> list[Path]:
    """Write the networks (both `Regressors`, or e.g. ``{"hand": net}`` from training) and the index; returns the
    files written."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    networks = networks._asdict() if isinstance(networks, Regressors) else dict(networks)
    index = dict(format=FORMAT, version=VERSION)
    written = []
    for kind, module in networks.items():
        _, state = nnx.split(module)
        arrays = {".".join(map(str, p)): np.asarray(v[...], np.float32) for p, v in nnx.to_flat_state(state)}
        path = out_dir / f"{kind}.npz"
        with atomic_path(path) as tmp:
            np.savez(tmp, **arrays)
        index[kind] = dict(file=path.name, sha256=file_sha256(path), config=dataclasses.asdict(module.config),
                           source=sources.get(kind, ""))
        written.append(path)
    atomic_write_text(out_dir / INDEX, json.dumps(index, indent=2) + "\n")
    return written + [out_dir / INDEX]


def load(directory: str | Path, *, dtype=None) -> Regressors:
    """The two networks from a folder written by ``jaxmocap convert-frankmocap``.

    ``dtype`` is the compute dtype (e.g. ``jnp.bfloat16``); weights stay float32.
    """
    index = _index(Path(directory))
    return Regressors(**{kind: _network(Path(directory), index, kind, dtype) for kind in _KINDS})


def load_network(directory: str | Path, kind: str, *, dtype=None) -> nnx.Module:
    """One network (``kind`` "hand" or "body") from a weights folder, e.g. one written by training."""
    if kind not in _KINDS:
        raise ValueError(f"kind: expected one of {sorted(_KINDS)}, got {kind!r}")
    return _network(Path(directory), _index(Path(directory)), kind, dtype)


def _index(directory: Path) -> dict:
    index_path = directory / INDEX
    if not index_path.is_file():
        raise WeightsError(f"{directory}: no {INDEX}; create the folder with "
                           "`jaxmocap convert-frankmocap --hand ... --hand-mean ... --body ... --out DIR`")
    try:
        index = json.loads(index_path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise WeightsError(f"{index_path}: not valid JSON ({err})") from None
    if index.get("format") != FORMAT or index.get("version") != VERSION:
        raise WeightsError(f"{index_path}: expected format {FORMAT} version {VERSION}, "
                           f"got {index.get('format')} version {index.get('version')}")
    return index


def _network(directory: Path, index: dict, kind: str, dtype) -> nnx.Module:
    entry = index.get(kind)
    if not isinstance(entry, dict) or not {"file", "sha256", "config"} <= set(entry):
        raise WeightsError(f"{directory / INDEX}: no complete '{kind}' entry (file, sha256, config)")
    try:
        config = _KINDS[kind][1](**entry["config"])
    except TypeError as err:
        raise WeightsError(f"{directory / INDEX}: bad '{kind}' config ({err})") from None
    path = directory / str(entry["file"])
    if not path.is_file() or file_sha256(path) != entry["sha256"]:
        raise WeightsError(f"{path}: missing or does not match the checksum in {INDEX}")
    try:
        with np.load(path, allow_pickle=False) as npz:
            arrays = {name: npz[name] for name in npz.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
        raise WeightsError(f"{path}: cannot read ({err})") from None
    return build(kind, config, arrays, str(path), dtype=dtype)


def _few(keys: list[str], n: int = 4) -> str:
    return ", ".join(keys[:n]) + (f" (+{len(keys) - n} more)" if len(keys) > n else "")
