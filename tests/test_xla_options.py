"""XLA's options: the older CPU fusion emitters asked for by each command before JAX starts, never over the user's;
OpenBLAS held to one thread for jaxlib's LAPACK; a library import that changes nothing in its host process."""

import os
import subprocess
import sys
from importlib import metadata
from pathlib import Path

from jaxmocap import xla_options
from jaxmocap.xla_options import set_cpu_options, set_lapack_threads

# Records XLA_FLAGS as JAX starts its backend (the moment XLA reads them) and ends the process there; before that,
# runs the statement given (an entry point).
SPY = """
import os, sys
from jax._src import xla_bridge
def spy(*args, **kwargs):
    print("XLA_FLAGS at start:", os.environ.get("XLA_FLAGS"), flush=True)
    os._exit(0)
xla_bridge._init_backend = spy
exec(sys.argv[1])
"""
DATA = Path(__file__).parent / "data"


def test_the_option_is_added_once_and_never_over_the_users():
    env = {"XLA_FLAGS": "--xla_force_host_platform_device_count=4"}
    assert set_cpu_options(env) and not set_cpu_options(env)
    assert env["XLA_FLAGS"] == "--xla_force_host_platform_device_count=4 --xla_cpu_use_fusion_emitters=false"
    mine = {"XLA_FLAGS": "--xla_cpu_use_fusion_emitters=true"}
    assert not set_cpu_options(mine) and mine["XLA_FLAGS"] == "--xla_cpu_use_fusion_emitters=true"
    empty = {}
    assert set_cpu_options(empty) and empty["XLA_FLAGS"] == "--xla_cpu_use_fusion_emitters=false"


def test_a_jaxlib_that_may_not_know_the_option_is_left_alone(monkeypatch):
    for version in ("0.4.36", "0.11.0"):
        monkeypatch.setattr(xla_options.metadata, "version", lambda name, v=version: v)
        env = {}
        assert not set_cpu_options(env) and env == {}
    assert xla_options._release(metadata.version("jaxlib")) >= (0, 5, 3)


def test_every_command_sets_it_before_jax_starts(tmp_path):
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    clip = DATA / "pose2sim_hand_closeup.mp4"
    for entry in (f"from jaxmocap.command import main; main(['fit', '{DATA / 'openpose'}', '--out', '{tmp_path}'])",
                  f"from train.main import main; main(['--config', 'smoke', '--workdir', '{tmp_path}'])",
                  "from jaxmocap.batch.task import run_video; from jaxmocap.pipeline import RunConfig; "
                  f"run_video(RunConfig('{clip}', mode='hands'), '{tmp_path}', '{tmp_path / 'mark'}', {{}})"):
        out = subprocess.run([sys.executable, "-c", SPY, entry], capture_output=True, text=True, env=env,
                             timeout=300, cwd=Path(__file__).parents[1])
        assert out.returncode == 0, out.stderr[-2000:]
        assert "XLA_FLAGS at start: --xla_cpu_use_fusion_emitters=false" in out.stdout, (entry, out.stdout)


# A library user's program: imports jaxmocap's packages, computes, and prints what changed in its environment.
IMPORTED = """
import os
import cv2, flax, jax, numpy, optax, optimistix, ray  # what they set on import is their own
before = dict(os.environ)
import jaxmocap, jaxmocap.pipeline, jaxmocap.integrate, jaxmocap.live, jaxmocap.batch, jaxmocap.detect, smplx_jax
import jax.numpy as jnp
jnp.linalg.cholesky(jnp.eye(3)).block_until_ready()
print(sorted(k for k in set(before) | set(os.environ) if before.get(k) != os.environ.get(k)))
"""


def test_importing_jaxmocap_changes_nothing_in_its_host_process():
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "OPENBLAS_NUM_THREADS")}
    out = subprocess.run([sys.executable, "-c", IMPORTED], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]", out.stdout


# Starts the command line (its help: nothing else), runs a Cholesky factorisation on the CPU (jaxlib loads scipy's
# OpenBLAS for it), then prints each OpenBLAS loaded in the process and its number of threads.
THREADS = """
import contextlib, ctypes, io
from jaxmocap.command import main
with contextlib.suppress(SystemExit), contextlib.redirect_stdout(io.StringIO()):
    main(["--help"])
import jax.numpy as jnp
jnp.linalg.cholesky(jnp.eye(3)).block_until_ready()
paths = sorted({line.split()[-1] for line in open("/proc/self/maps") if "openblas" in line.rsplit("/", 1)[-1]})
for path in paths:
    lib = ctypes.CDLL(path)
    count = next(getattr(lib, name) for name in ("scipy_openblas_get_num_threads64_", "scipy_openblas_get_num_threads",
                                                 "openblas_get_num_threads") if hasattr(lib, name))
    print(path, count())
"""


def test_lapack_runs_on_one_openblas_thread_unless_the_user_says():
    """Each OpenBLAS a jaxmocap process loads (scipy's, which jaxlib's LAPACK calls, among them) runs one thread:
    OpenBLAS's spinning threads made two processes on two cores some 40x slower (`xla_options`)."""
    # (OpenBLAS also reads GOTO_NUM_THREADS and OMP_NUM_THREADS, which conftest.py sets for PyTorch)
    unset = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")
    env = {k: v for k, v in os.environ.items() if k not in unset}
    out = subprocess.run([sys.executable, "-c", THREADS], capture_output=True, text=True, env=env, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    threads = dict(line.rsplit(" ", 1) for line in out.stdout.splitlines())
    assert any("scipy" in path for path in threads) and set(threads.values()) == {"1"}, threads
    mine, empty = {"OPENBLAS_NUM_THREADS": "4"}, {}
    assert not set_lapack_threads(mine) and mine == {"OPENBLAS_NUM_THREADS": "4"}
    assert set_lapack_threads(empty) and empty == {"OPENBLAS_NUM_THREADS": "1"}
