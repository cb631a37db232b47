"""jaxmocap: fast monocular 3D whole-body motion capture in JAX (a rebuild of FrankMocap)."""

__version__ = "0.1.0"
