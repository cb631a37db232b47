"""jaxmocap: fast monocular 3D whole-body motion capture in JAX (a rebuild of FrankMocap)."""

from jaxmocap.xla_options import set_cpu_options, set_lapack_threads

__version__ = "0.1.0"

set_cpu_options()  # before JAX starts: every module of the package (and of train) is imported after this
set_lapack_threads()  # before jaxlib loads scipy's OpenBLAS
