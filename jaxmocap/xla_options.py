"""XLA options for jaxmocap's programs, and the threads of the LAPACK they call, set for its own processes by each
command (`configure_process`: the CLI, the trainer, a batch's workers, the benchmarks) before JAX starts. A library
imported into someone's notebook or service sets nothing: its process's XLA and BLAS settings are its own.

XLA's newer CPU fusion emitters (its default in recent jaxlib) compile the fit's programs a third slower than its
older ones and run them no faster (docs/BENCHMARKS.md, "Compile time"), so the older ones are asked for (ResNets,
the regressors' and the trainer's, run 5-15% slower with the older ones; ``=true`` keeps the default). Only for
the jaxlib versions known to have the option (XLA stops a process whose ``XLA_FLAGS`` name an option it does not
know), and never over the user's own choice in ``XLA_FLAGS``.

jaxlib's LAPACK kernels on the CPU (the dense fit's Cholesky factorisations, `jnp.linalg`) run on scipy's OpenBLAS,
which jaxlib loads at its first such call. OpenBLAS's threads spin while they wait for work: two processes on two
cores (`jaxmocap batch --workers 2`, pytest's two workers) then fight over them, each many times slower than
alone; and alone, one thread is faster on matrices of the fit's size (178 x 178). So ``OPENBLAS_NUM_THREADS=1``,
unless the user set it (docs/BENCHMARKS.md, "LAPACK's threads")."""

import os
import re
from importlib import metadata

OPTION, VALUE = "xla_cpu_use_fusion_emitters", "false"
KNOWN_JAXLIB = ((0, 5, 3), (0, 11))  # the option exists in 0.5.3, 0.6.2, 0.7.2, 0.9.0 and 0.10.2 (checked)
# `jax.jit(..., compiler_options=RUN_ONCE)` for a program that runs once or a few times: LLVM at -O0 compiles it in
# about half the time (XLA's own passes and its arithmetic as ever, rounding aside) and runs it slower.
RUN_ONCE = {"xla_backend_optimization_level": 0}


def _release(version: str) -> tuple[int, ...]:
    return tuple(int(part) for part in re.match(r"(\d+)\.(\d+)\.(\d+)", version).groups())


def set_cpu_options(environ=os.environ) -> bool:
    """Add ``--xla_cpu_use_fusion_emitters=false`` to ``XLA_FLAGS`` unless it names the option already or jaxlib
    is outside `KNOWN_JAXLIB`; True when added."""
    flags = environ.get("XLA_FLAGS", "")
    try:
        release = _release(metadata.version("jaxlib"))
    except metadata.PackageNotFoundError:
        return False
    if OPTION in flags or not KNOWN_JAXLIB[0] <= release < KNOWN_JAXLIB[1]:
        return False
    environ["XLA_FLAGS"] = f"{flags} --{OPTION}={VALUE}".strip()
    return True


def configure_process(environ=os.environ) -> None:
    """What a command of jaxmocap sets for its own process (and those it starts) before JAX starts:
    `set_cpu_options` and `set_lapack_threads`, each never over the user's own setting."""
    set_cpu_options(environ)
    set_lapack_threads(environ)


def set_lapack_threads(environ=os.environ) -> bool:
    """``OPENBLAS_NUM_THREADS=1`` unless ``environ`` names a number already; True when set. It holds for each OpenBLAS
    loaded after it (scipy's, which jaxlib's LAPACK calls) and in the processes started from this one."""
    if "OPENBLAS_NUM_THREADS" in environ:
        return False
    environ["OPENBLAS_NUM_THREADS"] = "1"
    return True
