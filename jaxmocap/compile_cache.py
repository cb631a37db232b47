"""The on-disk cache of XLA's compiled programs that every jaxmocap process shares (``jaxmocap run``, each worker
of ``jaxmocap batch``): a program compiled once, by any of them, is read back by the others."""


def use_compilation_cache() -> None:
    """Keep XLA's compiled programs on disk (``$JAXMOCAP_CACHE/xla``, at most 1 GiB, least recently used out), so
    that a second run skips the compilation (docs/BENCHMARKS.md, "End to end"): every program, the small ones too
    (a run's ~140 programs under 0.5 s took 3-4 s to compile again in each run). ``JAX_COMPILATION_CACHE_DIR``
    takes precedence."""
    import jax

    from smplx_jax.default_model import cache_root

    if jax.config.jax_compilation_cache_dir is None:
        jax.config.update("jax_compilation_cache_dir", str(cache_root() / "xla"))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
        jax.config.update("jax_compilation_cache_max_size", 1 << 30)
