"""The on-disk caches that every jaxmocap process shares (``jaxmocap run``, each worker of ``jaxmocap batch``,
``jaxmocap live``): XLA's compiled programs, and the run's large programs as lowered by JAX (`jax.export`), so
that a program one process traced, lowered and compiled is read back by the others instead."""

import dataclasses
import functools
import hashlib
import importlib
import importlib.metadata
import inspect
import json
import os
import sys
import tempfile
from pathlib import Path

import jax

PROGRAMS_KEPT = 256  # lowered programs on disk at most (least recently used out): some 40-150 kB each
_TRACED_THROUGH = ("jax", "jaxlib", "equinox", "lineax", "optimistix")  # whose code the programs hold
_programs: list[Path | None] = [None]  # where lowered programs live (`keep_lowered_programs`)


def use_compilation_cache() -> None:
    """Keep XLA's compiled programs on disk (``$JAXMOCAP_CACHE/xla``, at most 1 GiB, least recently used out), so
    that a second run skips the compilation (docs/BENCHMARKS.md, "End to end"): every program, the small ones too
    (a run's ~140 programs under 0.5 s took 3-4 s to compile again in each run). ``JAX_COMPILATION_CACHE_DIR``
    takes precedence. The `disk_jit` programs go into its folder ``jaxmocap-programs``. The folders are made
    private to the user (0700); programs are loaded code, so a cache another user could write to is not used (a
    one-line warning; programs compile anew)."""
    from smplx_jax.default_model import cache_root, open_to_others, private_folder

    folder = Path(jax.config.jax_compilation_cache_dir or cache_root() / "xla")
    try:
        programs = private_folder(folder / "jaxmocap-programs")
    except OSError as err:  # a read-only or full disk: no cache, programs compile anew
        return _without_cache(f"cannot make {folder}/jaxmocap-programs ({err.strerror})")
    guarded = (folder, programs) + ((cache_root(),) if folder == cache_root() / "xla" else ())
    exposed = next((path for path in guarded if open_to_others(path)), None)
    if exposed is not None:
        return _without_cache(f"{exposed} is writable by other users")
    if jax.config.jax_compilation_cache_dir is None:
        jax.config.update("jax_compilation_cache_dir", str(folder))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_compilation_cache_max_size", 1 << 30)
    keep_lowered_programs(programs)


def _without_cache(why: str) -> None:
    """No compile cache in this process (one line on stderr saying ``why``): every program compiles anew."""
    print(f"jaxmocap: not using the compile cache: {why} (programs compile anew)", file=sys.stderr)
    jax.config.update("jax_compilation_cache_dir", None)
    keep_lowered_programs(None)


def keep_lowered_programs(folder: Path | None) -> None:
    """Where `disk_jit` keeps its lowered programs from now on (None: nowhere, the plain `jax.jit`)."""
    _programs[0] = folder


def disk_jit(fun=None, *, static_argnames: tuple[str, ...] | str = ()):
    """`jax.jit` whose lowered programs are also kept on disk (once `use_compilation_cache` or `keep_lowered_programs`
    named the folder): a new process that calls ``fun`` with arguments of the same structure, shapes and dtypes (and
    equal static ones) reads the program back in a fraction of a second instead of tracing and lowering it again
    (1-4 s for each of a run's large programs). Keyed by the function, its static arguments, its other arguments'
    tree, shapes and dtypes, JAX's tracing settings, the platform it runs on (the arguments' device: the live
    solve's CPU beside a GPU), the versions of the libraries traced through and the source of jaxmocap and
    smplx_jax: anything else that a program depends on (a module's constant) must live in those sources. Calls under
    a transformation, with several devices, with no folder named or with trees that cannot be written are the plain
    `jax.jit`."""
    if fun is None:
        return functools.partial(disk_jit, static_argnames=static_argnames)
    return _DiskJit(fun, (static_argnames,) if isinstance(static_argnames, str) else tuple(static_argnames))


class _DiskJit:
    """`disk_jit`'s function: its programs in memory, each read from or written to disk at its first call."""

    def __init__(self, fun, static_argnames: tuple[str, ...]):
        self.fun, self.static_argnames = fun, static_argnames
        self.jitted = jax.jit(fun, static_argnames=static_argnames)
        self.signature = inspect.signature(fun)
        self.programs = {}  # (static values, tree, avals, platform, settings) -> the program's call, or None
        functools.update_wrapper(self, fun)

    def __call__(self, *args, **kwargs):
        if _programs[0] is None or jax.device_count() > 1:
            return self.jitted(*args, **kwargs)
        bound = self.signature.bind(*args, **kwargs)
        bound.apply_defaults()
        static = tuple((k, v) for k, v in bound.arguments.items() if k in self.static_argnames)
        dynamic = {k: v for k, v in bound.arguments.items() if k not in self.static_argnames}
        leaves, tree = jax.tree.flatten(dynamic)
        avals, platform = _avals_and_platform(leaves)
        if platform is None:
            return self.jitted(*args, **kwargs)
        key = (static, tree, avals, platform, _settings())
        if key not in self.programs:
            self.programs[key] = self._load_or_export(static, dynamic, key)
        program = self.programs[key]
        return self.jitted(*args, **kwargs) if program is None else program(dynamic)

    def _load_or_export(self, static, dynamic, key):
        name = f"{self.fun.__module__}.{self.fun.__qualname__}"
        identity = repr((name, *key, _versions_and_sources()))
        path = _programs[0] / f"{hashlib.sha256(identity.encode()).hexdigest()[:40]}.jaxexport"
        exported = _read(path)
        if exported is None:
            try:
                exported = jax.export.export(jax.jit(functools.partial(self.fun, **dict(static))),
                                             platforms=(key[3],))(**dynamic)
                types = _custom_types(exported.in_tree, exported.out_tree)
                for cls in types:
                    _register_type(cls)
                blob = exported.serialize()
                if not _round_trips(exported, blob):
                    return None
            except (TypeError, ValueError, NotImplementedError):  # effects, trees that cannot be written
                return None
            _write(path, sorted((cls.__module__, cls.__qualname__) for cls in types), blob)

        def program(dynamic):
            return exported.call(**dynamic)

        program.__name__ = program.__qualname__ = self.fun.__name__  # JAX's logs and profiles name the function
        return jax.jit(program)


def _avals_and_platform(leaves) -> tuple[tuple, str | None]:
    """Each leaf's shape, dtype and weak type, and the platform the call runs on: that of the device its committed
    arrays are on, else JAX's default; None under a transformation (tracers) or across devices. One pass, reading
    attributes (a fraction of what ``jnp.result_type`` per leaf costs: it runs on every live frame)."""
    avals, devices = [], set()
    for x in leaves:
        if isinstance(x, jax.core.Tracer):
            return (), None
        if isinstance(x, jax.Array):
            avals.append((x.shape, x.dtype, x.weak_type))
            if x.committed:
                devices |= x.sharding.device_set
        else:
            avals.append((jax.numpy.shape(x), jax.numpy.result_type(x), isinstance(x, (bool, int, float, complex))))
    if len(devices) > 1:
        return (), None
    device = devices.pop() if devices else None
    if device is None or device.platform == jax.default_backend():
        return tuple(avals), jax.export.default_export_platform()
    return tuple(avals), "cpu" if device.platform == "cpu" else None  # the host beside an accelerator


def _settings() -> tuple:
    """JAX's settings that change what a trace gives."""
    config = jax.config
    return (config.jax_enable_x64, config.jax_default_matmul_precision, config.jax_numpy_dtype_promotion,
            config.jax_numpy_rank_promotion)


@functools.cache
def _versions_and_sources() -> str:
    digest = hashlib.sha256()
    for package in _TRACED_THROUGH:
        digest.update(f"{package}=={importlib.metadata.version(package)};".encode())
    for package in ("jaxmocap", "smplx_jax"):
        root = Path(importlib.import_module(package).__file__).parent
        for source in sorted(root.rglob("*.py")):
            digest.update(str(source.relative_to(root)).encode() + b"\0" + source.read_bytes())
    return digest.hexdigest()


# --- the files: a JSON line naming the node types of the trees in and out, then the serialized program ---

_OURS = ("jaxmocap.", "smplx_jax.")  # the packages whose tree node types a file may name (imported to register)


def _read(path: Path):
    try:
        header, blob = path.read_bytes().split(b"\n", 1)
        for module, qualname in json.loads(header):
            if not module.startswith(_OURS):
                return None
            cls = importlib.import_module(module)
            for part in qualname.split("."):
                cls = getattr(cls, part)
            _register_type(cls)
        exported = jax.export.deserialize(bytearray(blob))
        os.utime(path)  # recently used
        return exported
    except (OSError, ValueError, TypeError, AttributeError, ImportError):  # none yet, or unreadable: export anew
        return None


def _write(path: Path, node_types: list, blob: bytearray) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".tmp", delete=False) as f:
            f.write(json.dumps(node_types).encode() + b"\n" + bytes(blob))
        os.replace(f.name, path)
        kept = sorted(path.parent.glob("*.jaxexport"), key=lambda p: p.stat().st_mtime)
        for old in kept[:-PROGRAMS_KEPT]:
            old.unlink(missing_ok=True)
    except OSError:  # a read-only or full disk: the next process lowers again
        pass


def _round_trips(exported, blob) -> bool:
    again = jax.export.deserialize(blob)
    return again.in_tree == exported.in_tree and again.out_tree == exported.out_tree


# --- tree node types, registered for `jax.export` under their module and name, their static data as JSON ---

_registered: set[type] = set()
_BUILT_IN = (tuple, list, dict, type(None))


def _custom_types(*trees) -> set[type]:
    """The node types of ``trees`` other than tuples, lists, dicts and None."""
    found, todo = set(), list(trees)
    while todo:
        node = todo.pop()
        data = node.node_data()
        if data is not None and data[0] not in _BUILT_IN:
            found.add(data[0])
        todo += node.children()
    return found


def _register_type(cls: type) -> None:
    if cls in _registered:
        return
    if not cls.__module__.startswith(_OURS):
        raise TypeError(f"cannot write a tree holding {cls}")
    name = f"jaxmocap:{cls.__module__}.{cls.__qualname__}"
    if issubclass(cls, tuple) and hasattr(cls, "_fields"):
        jax.export.register_namedtuple_serialization(cls, serialized_name=name)
    elif dataclasses.is_dataclass(cls):
        jax.export.register_pytree_node_serialization(
            cls, serialized_name=name, serialize_auxdata=lambda aux: json.dumps(aux).encode(),
            deserialize_auxdata=lambda data: _tuples(json.loads(data)))
    else:
        raise TypeError(f"cannot write a tree holding {cls}")
    _registered.add(cls)


def _tuples(value):
    """JSON's lists back into the tuples they were."""
    return tuple(_tuples(v) for v in value) if isinstance(value, list) else value
