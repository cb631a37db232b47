"""Shared fixtures: model files (random with official shapes, and the default model), loaded once; a run
interrupted on purpose."""

import contextlib
import functools
import itertools
import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from jaxtyping import install_import_hook

# The tests check every call of the packages' functions and dataclasses against their annotations (jaxtyping's
# shapes and dtypes, beartype the rest), as optimistix's tests do. The hook must be in place before the packages
# are first imported, so it is installed here and not by `--jaxtyping-packages=...` in addopts: jaxtyping's
# plugin (0.3.11) splits a typechecker that takes arguments from one package only, and beartype needs them here:
# the numeric tower (an int where a float is annotated, as PEP 484 allows) and every item of containers checked.
install_import_hook(
    ["smplx_jax", "jaxmocap", "train"],
    "beartype.beartype(conf=beartype.BeartypeConf(is_pep484_tower=True, strategy=beartype.BeartypeStrategy.On))")

sys.path.insert(0, str(Path(__file__).parent))


def pytest_configure(config):
    """One on-disk cache of compiled programs for the whole run, new and empty (as on a new machine; not the
    user's ``~/.cache/jaxmocap/xla``), shared by pytest-xdist's workers and the subprocesses tests start, so that a
    program one test compiled is read back by another (the suite's time is mostly XLA compiling). Each worker keeps
    its `jaxmocap.compile_cache.disk_jit` programs there as lowered from its start, as the CLI does: a run in a
    worker and ``jaxmocap run`` in a subprocess then compile the same programs, whichever test ran first (a plain
    `jax.jit` of the same function is another program). The controller names the folder; the workers inherit its
    environment. PyTorch (the peers) computes on one thread per process, set before it is first imported: its
    OpenMP threads spin while they wait, and with the other worker busy on the other core a loop of small products
    ran 12x slower on two threads (11.5 s against 1.0 s alone) and as fast as alone on one (1.3 s)."""
    import jax

    from jaxmocap.compile_cache import use_compilation_cache

    if "JAXMOCAP_TEST_CACHE" not in os.environ or not hasattr(config, "workerinput"):
        os.environ["JAXMOCAP_TEST_CACHE"] = tempfile.mkdtemp(prefix="jaxmocap-tests-")
    cache = str(Path(os.environ["JAXMOCAP_TEST_CACHE"]) / "xla")
    os.environ["JAX_COMPILATION_CACHE_DIR"] = cache
    os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
    use_compilation_cache()


# The files that take longest, longest first (`pytest --durations=0`, summed per file, 2026-11-26): the workers
# take files in this order, so the long ones start first and the short ones fill in at the end (`-n 2 --dist
# loadfile` with `--no-loadscope-reorder`, pyproject.toml).
LONGEST_FIRST = ("test_pipeline.py", "test_fit_gradients.py", "test_integrate.py", "test_hands.py",
                 "test_real_footage.py", "test_train.py", "test_fit_frame.py", "test_live.py", "test_batch.py",
                 "test_eft.py", "test_multi_person.py", "test_readme.py", "test_regressors.py", "test_sharding.py")


def pytest_collection_modifyitems(items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(rank)))  # stable: each file keeps its own order


def pytest_unconfigure(config):
    if not hasattr(config, "workerinput"):  # the controller (or a run without workers), after all of them
        shutil.rmtree(os.environ["JAXMOCAP_TEST_CACHE"], ignore_errors=True)


import jax  # noqa: E402

from jaxmocap.xla_options import configure_process  # noqa: E402

configure_process()  # as the commands do, before anything starts JAX (the tests' processes are the project's own)
import smplx_jax  # noqa: E402
from jaxmocap.xla_options import RUN_ONCE  # noqa: E402
from random_model import random_model_arrays  # noqa: E402
from smplx_jax.default_model import default_model_path  # noqa: E402


@pytest.fixture(scope="session")
def random_model_dir(tmp_path_factory) -> Path:
    """A folder ``smplx.create`` reads: ``<dir>/smplx/SMPLX_NEUTRAL.npz`` with random official-shaped arrays."""
    root = tmp_path_factory.mktemp("random_model")
    (root / "smplx").mkdir()
    np.savez(root / "smplx" / "SMPLX_NEUTRAL.npz", **random_model_arrays(seed=0))
    return root


@pytest.fixture(scope="session")
def default_model_dir() -> Path:
    return default_model_path().parent.parent


@pytest.fixture(scope="session", params=["default", "random"])
def model_dir(request, default_model_dir, random_model_dir) -> Path:
    return default_model_dir if request.param == "default" else random_model_dir


@pytest.fixture(scope="module")
def x64():
    """Float64 throughout the module that asks for it."""
    import jax

    with jax.enable_x64(True):
        yield


_LOADED = {}


def load(model_dir: Path) -> smplx_jax.BodyModel:
    """Each model file is loaded once per session."""
    if model_dir not in _LOADED:
        _LOADED[model_dir] = smplx_jax.load_model(model_dir / "smplx" / "SMPLX_NEUTRAL.npz")
    return _LOADED[model_dir]


def _ctrl_c():
    raise KeyboardInterrupt


@contextlib.contextmanager
def interrupted_at_chunk(monkeypatch, index: int, stop=_ctrl_c):
    """Within the block, ``jaxmocap run`` calls ``stop`` (default: KeyboardInterrupt, as Ctrl-C) when it comes to
    solve its chunk number ``index`` (0-based; stored chunks are not solved again)."""
    import jaxmocap.pipeline.job as job

    solve, calls = job.solve_chunk, []

    def solve_or_stop(*args):
        calls.append(1)
        if len(calls) == index + 1:
            stop()
        return solve(*args)

    monkeypatch.setattr(job, "solve_chunk", solve_or_stop)
    try:
        yield
    finally:
        monkeypatch.setattr(job, "solve_chunk", solve)


@contextlib.contextmanager
def frames_alive_at_each_chunk(monkeypatch):
    """Within the block, a list with, as a run (`pipeline.job` or `pipeline.hands_job`, both through
    `pipeline.chunks.stored_or_solved`) starts reading each chunk of frames, how many of the previous chunk's
    frames are still held anywhere (weak references, after a collection): a run must hold one chunk of decoded
    frames at a time."""
    import gc
    import weakref

    from jaxmocap.pipeline import chunks

    batches, alive, previous = chunks.frame_batches, [], []

    def watched(frames, size, clock):
        def counted():
            for count, (index, frame) in zip(itertools.count(), frames):
                if count % size == 0:
                    gc.collect()
                    alive.append(sum(ref() is not None for ref in previous))
                    previous.clear()
                previous.append(weakref.ref(frame))
                yield index, frame
                del frame

        return batches(counted(), size, clock)

    monkeypatch.setattr(chunks, "frame_batches", watched)
    try:
        yield alive
    finally:
        monkeypatch.setattr(chunks, "frame_batches", batches)


@contextlib.contextmanager
def programs_lowered():
    """Within the block, a list with the name of each program JAX lowers (``jit(<function>)``; none for a program
    it holds already), from `jax.monitoring`'s events."""
    lowered = []

    def count(event, seconds, **kwargs):
        if event == "/jax/core/compile/jaxpr_to_mlir_module_duration":
            lowered.append(kwargs.get("fun_name", "?"))

    jax.monitoring.register_event_duration_secs_listener(count)
    try:
        yield lowered
    finally:
        jax.monitoring.unregister_event_duration_listener(count)


def temporary_files(folder: Path) -> list[Path]:
    """What an atomic write leaves behind if it is cut short (`smplx_jax.atomic_files.atomic_path`'s names)."""
    return [p for p in folder.rglob(".*") if ".tmp" in p.name]


def cli_as_from_a_terminal(*args: str, python_options: tuple[str, ...] = ()) -> list[str]:
    """The command line of ``jaxmocap ARGS`` that Ctrl-C (SIGINT) interrupts, as in a terminal. A background job
    (CI's, nohup's, a shell's ``cmd &``) inherits SIGINT ignored, its subprocesses too, and Python then leaves it
    ignored: the tests' SIGINT would be lost."""
    start = ("import signal, sys; signal.signal(signal.SIGINT, signal.default_int_handler); "
             "from jaxmocap.command import entry; entry()")
    return [sys.executable, *python_options, "-c", start, *args]


# LLVM at -O0 (`xla_options.RUN_ONCE`) for the tests' own programs that compile for seconds and then run a handful
# of times (the fit's gradients and Jacobians, jit = eager, the 4-device processes), which do not feel its slower
# runs (docs/BENCHMARKS.md, "Tests that share their programs", "Programs that run once"). `FAST_COMPILE_FLAG`: the
# same for a new process.
jit_fast_compile = functools.partial(jax.jit, compiler_options=RUN_ONCE)
FAST_COMPILE_FLAG = " ".join(f"--{option}={value}" for option, value in RUN_ONCE.items())


def with_four_cpu_devices(**env: str) -> dict[str, str]:
    """The environment of a subprocess that has 4 CPU devices (the sharding tests), compiling at `FAST_COMPILE_FLAG`;
    ``env`` added."""
    return os.environ | {"XLA_FLAGS": f"--xla_force_host_platform_device_count=4 {FAST_COMPILE_FLAG}",
                         "JAX_PLATFORMS": "cpu"} | env


CLIP = Path(__file__).parents[1] / "jaxmocap" / "data" / "pose2sim_single_cam01.mp4"
WEIGHTS_RUN_FRAMES = (20, 28)  # the frames of the sample clip that `frankmocap_run` solves, in chunks of 4


@pytest.fixture(scope="session")
def frankmocap(tmp_path_factory):
    """FrankMocap-format files of random reference networks (`frankmocap_reference.write_checkpoints`), converted
    by ``jaxmocap convert-frankmocap`` once per session: ``(folder, hand, body)``, the PyTorch reference modules
    beside the folder that holds the files and the converted ``weights``."""
    import frankmocap_reference as ref
    from jaxmocap.cli import main

    root = tmp_path_factory.mktemp("frankmocap")
    hand, body = ref.write_checkpoints(root)
    assert main(["convert-frankmocap", "--hand", str(root / "pose_shape_best.pth"), "--hand-mean",
                 str(root / "mean_mano_params.pkl"), "--body", str(root / "body.pt"), "--out",
                 str(root / "weights")]) == 0
    return root, hand, body


@pytest.fixture(scope="session")
def frankmocap_run(frankmocap, tmp_path_factory):
    """``frankmocap_run(**options)``: the output folder of ``jaxmocap run`` with the converted weights on
    `WEIGHTS_RUN_FRAMES` (no smoothing, no overlay, FrankMocap's pickles written), once per session for each set of
    options (``integration``, ``mode``, ``hand_boxes``, ``end``)."""
    from jaxmocap.pipeline import RunConfig, run

    start, end = WEIGHTS_RUN_FRAMES
    defaults = dict(weights=frankmocap[0] / "weights", start=start, end=end, chunk_size=4, smooth=False,
                    overlay=False, progress=False, frankmocap_pkl=True)
    done = {}

    def weights_run(**options) -> Path:
        config = RunConfig(CLIP, **defaults | options)  # options equal to the defaults give the same run
        if config not in done:
            done[config] = tmp_path_factory.mktemp("frankmocap_run")
            run(config, done[config])
        return done[config]

    return weights_run


# upper arms, forearms, thighs, shins
LIMB_BONES = ((16, 18), (17, 19), (18, 20), (19, 21), (1, 4), (2, 5), (4, 7), (5, 8))


def assert_kept_for_the_next_process(*functions) -> None:
    """Each of these `jaxmocap.compile_cache.disk_jit` functions was called in this process and every program of
    it was written as it lowered (none fell back to a plain `jax.jit`): a new process (`jaxmocap run`, a `batch`
    worker, `live`) reads them back instead of tracing them again."""
    held = {f.__qualname__: list(f.programs.values()) for f in functions}
    assert [name for name, programs in held.items() if not programs or None in programs] == []


def assert_one_body(motion: dict, frames=slice(None)) -> None:
    """One shape for the person over ``frames`` of ``motion``'s valid ones: ``betas`` the same row (per-component
    std <= 0.01) and the limb bones' lengths within 0.5% of their median."""
    from jaxmocap.buckets import map_in_buckets
    from jaxmocap.integrate.fitting import BUCKETS
    from jaxmocap.motion import motion_params

    model = load(default_model_path().parent.parent)
    valid = np.flatnonzero(motion["valid"])[frames]
    assert len(valid) >= 2 and motion["betas"][valid].std(0).max() <= 0.01, motion["betas"][valid].std(0)
    joints = np.asarray(map_in_buckets(  # the run's batch sizes: a few compiled programs for any number of frames
        lambda chunk, _: jax.vmap(smplx_jax.forward_joints, in_axes=(None, 0))(model, chunk),
        motion_params(motion, model.num_expression, valid), BUCKETS))
    for a, b in LIMB_BONES:
        length = np.linalg.norm(joints[:, a] - joints[:, b], axis=-1)
        assert np.ptp(length) <= 0.005 * np.median(length), (a, b, length.min(), length.max())
