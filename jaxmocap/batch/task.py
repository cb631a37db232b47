"""One video of a batch, as a Ray worker runs it: ``jaxmocap run``'s job (`pipeline.run`) into its folder, then its
mark. Imports no Ray: the worker calls `run_video` like any function."""

import time
from pathlib import Path

import numpy as np

from jaxmocap.batch.ledger import VideoRecord, write_mark
from jaxmocap.compile_cache import use_compilation_cache
from jaxmocap.errors import InputError
from jaxmocap.pipeline import RunConfig, run
from jaxmocap.result_files import read_result_npz
from jaxmocap.signals import cancellable
from jaxmocap.xla_options import configure_process
from smplx_jax import ModelFileError


def run_video(config: RunConfig, out: str, mark: str, key: dict) -> VideoRecord:
    """``run(config, out)``, resumed from its stored chunks if an earlier try stopped, then the mark of the
    finished video (``mark``: its path; ``key``: `ledger.video_key`). Any error of the run is the video's failed
    record with its one-line cause, not an exception: one bad input stops nothing else. Ctrl-C (Ray's cancel)
    passes through, wherever in the run it lands (`signals.cancellable`), after the run's atomic writes roll
    back."""
    configure_process()  # the worker's own process, as the command's (`xla_options`)
    use_compilation_cache()  # a program any worker compiled before is read back, not compiled again
    started = time.perf_counter()
    Path(mark).unlink(missing_ok=True)  # the outputs are being rewritten: not finished until marked again
    try:
        with cancellable():
            report = run(config, out)
    except (InputError, ModelFileError, OSError) as err:
        return VideoRecord.failure(str(config.source), out, str(err), time.perf_counter() - started)
    except Exception as err:  # a video the job cannot solve fails alone, however it fails
        return VideoRecord.failure(str(config.source), out, f"{type(err).__name__}: {err}",
                                   time.perf_counter() - started)
    record = VideoRecord(str(config.source), out, "done", None, report.frames, len(report.people), report.valid,
                         median_reprojection(report.motion, config.mode), round(time.perf_counter() - started, 3))
    write_mark(Path(mark), key, record)
    return record


def median_reprojection(path: Path, mode: str) -> float | None:
    """The median reprojection error (pixels) over the valid frames of a motion.npz, or of both hands of a
    hands.npz; None without any."""
    arrays = read_result_npz(path, "hands" if mode == "hands" else "motion")
    sides = ("left_", "right_") if mode == "hands" else ("",)
    errors = np.concatenate([arrays[f"{s}reprojection_error_px"][arrays[f"{s}valid"]] for s in sides])
    return round(float(np.median(errors)), 3) if len(errors) else None
