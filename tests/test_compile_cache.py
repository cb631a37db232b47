"""`compile_cache.disk_jit`: a lowered program is read back from disk by the next process instead of traced again,
keyed as JAX keys its programs (another argument structure, shape, dtype, weak type or static value gets its
own; NumPy arrays share the program of the arrays JAX makes of them); unreadable or foreign files are exported
anew (and import nothing); calls under a transformation are `jax.jit`'s."""

import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from conftest import programs_lowered
from jaxmocap import compile_cache
from jaxmocap.compile_cache import disk_jit

_TWO_PROCESSES = """
import jax.numpy as jnp, numpy as np
from jaxmocap.compile_cache import disk_jit, use_compilation_cache
from jaxmocap.integrate.keypoints import params_of
from jaxmocap.integrate.least_squares import Unknowns

traced = []

@disk_jit(static_argnames="num_expression")
def params(y, num_expression):  # a tree of this package's types in (a NamedTuple) and out (a pytree dataclass)
    traced.append(1)
    return params_of(jnp.sin(y.pose_rotvecs), y.betas * 2, num_expression)

use_compilation_cache()
y = Unknowns(np.linspace(0, 1, 165, dtype=np.float32).reshape(55, 3), np.ones(10, np.float32), np.zeros(3))
out = params(y, num_expression=10)
print(len(traced), float(jnp.sum(out.body_pose)), float(jnp.sum(out.betas)), out.expression.shape)
"""


# Where a process's compile caches go after `use_compilation_cache`, and the modes of the folders it made.
_CACHE_USED = """
import os, stat, sys, jax
from jaxmocap.compile_cache import _programs, use_compilation_cache
use_compilation_cache()
root = os.environ["JAXMOCAP_CACHE"]
modes = {name: oct(stat.S_IMODE(os.stat(os.path.join(root, *name.split("/"))).st_mode))
         for name in ("", "xla", "xla/jaxmocap-programs") if os.path.exists(os.path.join(root, *name.split("/")))}
print(jax.config.jax_compilation_cache_dir, _programs[0], modes)
"""


def test_cache_folders_are_private_and_one_others_can_write_is_not_loaded(tmp_path):
    """Compiled programs are loaded as code: the caches are made readable by their user alone (0700), and a cache
    folder a group or others may write to is not used (one line on stderr; programs compile anew)."""
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"}

    def used(root):
        out = subprocess.run([sys.executable, "-c", _CACHE_USED], env=env | {"JAXMOCAP_CACHE": str(root)},
                             capture_output=True, text=True, timeout=120)
        assert out.returncode == 0, out.stderr[-2000:]
        return out.stdout.split(" ", 2), out.stderr

    (folder, programs, modes), stderr = used(tmp_path / "new" / "cache")
    assert folder == str(tmp_path / "new" / "cache" / "xla") and programs == f"{folder}/jaxmocap-programs"
    assert modes.strip() == str({"": "0o700", "xla": "0o700", "xla/jaxmocap-programs": "0o700"}) and not stderr
    for shared in (tmp_path / "shared", tmp_path / "shared_xla" / "xla"):
        shared.mkdir(parents=True)
        shared.chmod(0o777)  # another user could put programs here
        root = shared if shared.name == "shared" else shared.parent
        (folder, programs, _), stderr = used(root)
        assert (folder, programs) == ("None", "None"), (shared, folder)
        assert len(stderr.splitlines()) == 1 and "writable by other users" in stderr and str(shared) in stderr


def test_a_new_process_reads_the_program_back_instead_of_tracing_it(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "JAX_COMPILATION_CACHE_DIR"} | {"JAXMOCAP_CACHE": str(tmp_path)}
    runs = [subprocess.run([sys.executable, "-c", _TWO_PROCESSES], env=env, capture_output=True, text=True)
            for _ in range(2)]
    assert all(r.returncode == 0 for r in runs), runs[-1].stderr[-2000:]
    first, second = (r.stdout.split() for r in runs)
    assert first[0] == "1" and second[0] == "0", (first, second)  # the second process traced nothing
    assert first[1:] == second[1:]
    assert len(list((tmp_path / "xla" / "jaxmocap-programs").glob("*.jaxexport"))) == 1


@pytest.fixture
def programs(tmp_path, monkeypatch):
    monkeypatch.setattr(compile_cache, "_programs", [tmp_path])
    return tmp_path


traces = []


def scaled(x, y, n: int):
    """``y``: any tree of arrays."""
    traces.append(1)
    return {"sum": x * n + sum(jnp.sum(leaf) for leaf in jax.tree.leaves(y)), "n": jnp.full((n,), x.sum())}


def files(folder):
    return sorted(folder.glob("*.jaxexport"))


def equal(a, b) -> bool:
    return jax.tree.structure(a) == jax.tree.structure(b) and all(map(np.array_equal, jax.tree.leaves(a),
                                                                      jax.tree.leaves(b)))


def test_one_file_per_structure_shape_dtype_and_static_value(programs):
    traces.clear()
    x, y = jnp.arange(3.0), jnp.ones((2, 2))
    expected = jax.jit(scaled, static_argnames="n")(x, y, n=2)
    first = disk_jit(scaled, static_argnames="n")
    assert equal(first(x, y, n=2), expected)
    assert len(traces) == 2 and len(files(programs)) == 1 and len(first.programs) == 1
    assert [p.__name__ for p in first.programs.values()] == ["scaled"]  # as JAX's compile logs and profiles name it
    first(x + 1, y, 2)  # other values, the static one by position: the same program
    assert len(traces) == 2 and len(first.programs) == 1
    again = disk_jit(scaled, static_argnames="n")  # as in a new process: nothing in memory
    assert equal(again(x, y, n=2), expected) and len(traces) == 2
    assert equal(again(np.asarray(x), np.asarray(y, np.float64), 2), expected) and len(traces) == 2  # as JAX sees
    for args in ((x, y, 3), (x[:2], y, 2), (x.astype(jnp.int32), y, 2), (x, {"a": y}, 2), (x, jnp.float32(1), 2),
                 (x, 1.0, 2)):  # the last two differ in their weak type alone
        again(*args)
    assert len(traces) == 8 and len(files(programs)) == 7


def test_calls_under_a_transformation_are_jits(programs):
    f = disk_jit(scaled, static_argnames="n")
    xs, y = jnp.arange(6.0).reshape(2, 3), jnp.ones(2)
    np.testing.assert_allclose(jax.vmap(f, in_axes=(0, None, None))(xs, y, 2)["sum"], xs * 2 + 2)
    np.testing.assert_allclose(jax.grad(lambda x: f(x, y, 2)["sum"].sum())(xs[0]), 2.0)
    assert files(programs) == [] and f.programs == {}


def test_an_unreadable_or_foreign_file_is_exported_anew_and_imports_nothing(programs, tmp_path_factory, monkeypatch):
    """A file that names a module outside jaxmocap and smplx_jax for its trees' types is not read (the module
    would be imported)."""
    traces.clear()
    x, y = jnp.arange(3.0), jnp.ones(2)
    expected = disk_jit(scaled, static_argnames="n")(x, y, 2)
    (path,) = files(programs)
    blob = path.read_bytes().split(b"\n", 1)[1]
    marker = tmp_path_factory.mktemp("marker") / "imported"
    module = tmp_path_factory.mktemp("modules")
    (module / "foreign_types.py").write_text(f"open({str(marker)!r}, 'w').close()\nclass T: pass\n")
    monkeypatch.syspath_prepend(str(module))
    for content in (b"garbage", b'[["foreign_types", "T"]]\n' + blob):
        path.write_bytes(content)
        assert equal(disk_jit(scaled, static_argnames="n")(x, y, 2), expected)
        assert not marker.exists() and "foreign_types" not in sys.modules
        assert path.read_bytes().startswith(b"[]\n") and compile_cache._read(path) is not None  # written again
    assert len(traces) == 3


def test_least_recently_used_programs_go(programs, monkeypatch):
    monkeypatch.setattr(compile_cache, "PROGRAMS_KEPT", 2)
    traces.clear()
    f = disk_jit(scaled, static_argnames="n")
    for n in (1, 2, 3):
        f(jnp.ones(1), jnp.ones(1), n)
    assert len(files(programs)) == 2 and len(traces) == 3
    again = disk_jit(scaled, static_argnames="n")
    again(jnp.ones(1), jnp.ones(1), 3)
    assert len(traces) == 3  # kept
    again(jnp.ones(1), jnp.ones(1), 1)
    assert len(traces) == 4  # gone, traced again


def test_off_until_the_cache_is_on(monkeypatch):
    monkeypatch.setattr(compile_cache, "_programs", [None])
    f = disk_jit(scaled, static_argnames="n")
    x, y = jnp.ones(1), jnp.ones(1)
    with programs_lowered() as lowered:
        np.testing.assert_allclose(f(x, y, 4)["sum"], 5.0)
    assert f.programs == {} and lowered == ["jit(scaled)"], lowered  # jax.jit's
