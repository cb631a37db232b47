"""A Ctrl-C, SIGTERM or Ray's cancel is never dropped: one whose handler runs inside a garbage collector's callback
(as JAX's runs after each collection) is raised again in ordinary code (`jaxmocap.signals.interrupts_kept`), and
`cancellable` work stops on Ctrl-C even where SIGINT was inherited ignored.

A batch's SIGTERM let the video run to its end: its Ray workers, started from a background job, ignored Ray's
cancel (a SIGINT); and once the cancel landed in JAX's callback (the worker's log: "Exception ignored in: <function
_xla_gc_callback ...> KeyboardInterrupt").
"""

import _thread
import gc
import signal
import sys
import time

import pytest

from jaxmocap.batch import task
from jaxmocap.pipeline import RunConfig
from jaxmocap.signals import Terminated, cancellable, handling, interrupts_kept


def collect_interrupted(signum: int) -> None:
    """A collection whose callback is interrupted by ``signum`` (its handler runs there, in the callback)."""
    def callback(phase, info):
        if phase == "stop":
            _thread.interrupt_main(signum)
            for _ in range(1000):  # Python code: the pending signal's handler runs here
                pass
    gc.callbacks.append(callback)
    try:
        gc.collect()
    finally:
        gc.callbacks.remove(callback)


def go_on(seconds: float = 1.0) -> str:
    """Ordinary code after the collection, where a kept interrupt is raised."""
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        pass
    return "went on"


def raise_terminated(signum, frame):
    raise Terminated


@pytest.fixture(autouse=True)
def ctrl_c_raises():
    """Python's own SIGINT handler (a test worker may have been started with SIGINT ignored)."""
    with handling(signal.default_int_handler, signal.SIGINT):
        yield


def test_python_drops_an_interrupt_raised_in_a_gc_callback(monkeypatch):
    dropped = []
    monkeypatch.setattr(sys, "unraisablehook", dropped.append)
    collect_interrupted(signal.SIGINT)
    assert go_on() == "went on"
    assert [d.exc_type for d in dropped] == [KeyboardInterrupt]


def test_ctrl_c_in_a_gc_callback_is_raised_again():
    with interrupts_kept(), pytest.raises(KeyboardInterrupt) as raised:
        collect_interrupted(signal.SIGINT)
        go_on()
    assert type(raised.value) is KeyboardInterrupt


def test_sigterm_in_a_gc_callback_is_raised_again_as_terminated():
    with handling(raise_terminated, signal.SIGTERM), interrupts_kept(), pytest.raises(KeyboardInterrupt) as raised:
        collect_interrupted(signal.SIGTERM)
        go_on()
    assert type(raised.value) is Terminated


def test_other_unraisable_errors_reach_the_previous_hook(monkeypatch):
    seen = []
    monkeypatch.setattr(sys, "unraisablehook", seen.append)

    class Finalised:
        def __del__(self):
            raise ValueError("in a finaliser")

    with interrupts_kept():
        Finalised()
    assert [s.exc_type for s in seen] == [ValueError]
    assert sys.unraisablehook == seen.append  # put back


def test_a_cancel_landing_in_a_gc_callback_stops_a_batchs_video(monkeypatch, tmp_path):
    """Ray cancels a running task by a SIGINT to its thread: `run_video` passes it on even from a callback."""
    def run(config, out):
        collect_interrupted(signal.SIGINT)
        go_on()
        raise AssertionError("the run went on")

    monkeypatch.setattr(task, "run", run)
    with pytest.raises(KeyboardInterrupt):
        task.run_video(RunConfig("clip.mp4"), str(tmp_path), str(tmp_path / "mark"), {})


def test_cancellable_work_stops_on_ctrl_c_where_sigint_was_inherited_ignored():
    """A background job's processes (and Ray's workers it starts) inherit SIGINT ignored; Ray's cancel is a SIGINT."""
    with handling(signal.SIG_IGN, signal.SIGINT), cancellable(), pytest.raises(KeyboardInterrupt):
        _thread.interrupt_main()
        go_on()
