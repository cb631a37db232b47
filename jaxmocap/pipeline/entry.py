"""`run`: the one entry of ``jaxmocap run``, ``demo`` and ``batch`` for every ``--mode``; it dispatches to the
bodies' job (`job.run_bodies`: ``whole`` and ``body``) or the hands' (`hands_job.run_hands`). The jobs import
neither each other nor this module."""

from pathlib import Path

from jaxmocap.pipeline.config import RunConfig
from jaxmocap.pipeline.hands_job import run_hands
from jaxmocap.pipeline.job import Observer, run_bodies
from jaxmocap.pipeline.report import RunReport
from smplx_jax.atomic_files import remove_abandoned


def run(config: RunConfig, out_dir, observed: Observer | None = None) -> RunReport:
    """Run ``config`` into ``out_dir`` (docs/formats.md): ``motion.npz`` and each person's for ``--mode whole`` and
    ``body``, ``hands.npz`` for ``hands``. ``observed(chunk, people)`` sees each body chunk solved (`run_bodies`);
    the hands' job has no body observations to show. Temporary files that a killed run left in ``out_dir`` (a
    worker of ``batch`` killed mid-write, then retried) are removed first."""
    if Path(out_dir).is_dir():
        remove_abandoned(out_dir)
    if config.mode == "hands":
        if observed is not None:
            raise ValueError("observed: --mode hands has no body observations")
        return run_hands(config, out_dir)
    return run_bodies(config, out_dir, observed)
