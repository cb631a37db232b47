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
import subprocess
import sys
import threading
import time

import pytest

from conftest import CLIP
from jaxmocap.batch import task
from jaxmocap.frame_source import open_media
from jaxmocap.pipeline import RunConfig
from jaxmocap.signals import Terminated, cancellable, handling, interrupt_of, interrupts_kept


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


def test_the_signal_an_exception_stands_for():
    def raised(cause: BaseException, wrapped: bool):
        try:
            try:
                raise cause
            except BaseException as err:
                if wrapped:
                    raise ImportError("initialization failed") from err
                raise ValueError("while stopping")  # noqa: B904 (the interrupt, its context)
        except BaseException as err:
            return err

    assert interrupt_of(KeyboardInterrupt()) == signal.SIGINT and interrupt_of(Terminated()) == signal.SIGTERM
    assert interrupt_of(raised(KeyboardInterrupt(), True)) == signal.SIGINT  # a C extension's import, cut short
    assert interrupt_of(raised(Terminated(), False)) == signal.SIGTERM  # an error raised while stopping
    assert interrupt_of(raised(OSError(), True)) is None and interrupt_of(ValueError()) is None


# The command's process, an interrupt given at one moment of it: ``{moment}`` is Python code run there.
COMMAND_AT = """
import atexit, importlib.abc, os, signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)
class Moment(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path, target=None):
        if name == "jaxmocap.cli":
            sys.meta_path.remove(self)
            {moment}
sys.meta_path.insert(0, Moment())
from jaxmocap.command import main
sys.exit(main(["model", "--help"]))
"""
MOMENTS = {
    "in an import": "os.kill(os.getpid(), signal.SIGINT); time.sleep(1)",
    "in a C extension's import": "raise ImportError('initialization failed') from KeyboardInterrupt()",
    "swallowed by a C extension's import": ("exec('try:\\n os.kill(os.getpid(), signal.SIGINT)\\n time.sleep(1)\\n"
                                            "except KeyboardInterrupt:\\n pass'); "
                                            "raise ImportError('numpy._core.multiarray failed to import')"),
    "a SIGTERM in an import": "os.kill(os.getpid(), signal.SIGTERM); time.sleep(1)",
    "as the process exits": "atexit.register(lambda: (os.kill(os.getpid(), signal.SIGINT), time.sleep(1)))",
}


@pytest.mark.parametrize("moment", MOMENTS)
def test_an_interrupt_at_any_moment_of_the_command_ends_it_with_one_line(moment):
    """Ctrl-C or SIGTERM while the command starts: 130 or 143 and one line; once it has ended (Python's exit
    callbacks, its threads joined), nothing: the command's own exit code, no traceback."""
    out = subprocess.run([sys.executable, "-c", COMMAND_AT.format(moment=MOMENTS[moment])], capture_output=True,
                         text=True, timeout=120)
    if moment == "as the process exits":
        assert out.returncode == 0 and "usage: jaxmocap model" in out.stdout and out.stderr == "", out.stderr
    else:
        sigterm = "SIGTERM" in moment
        assert out.returncode == (143 if sigterm else 130), out.stderr
        assert out.stderr == f"jaxmocap: {'terminated' if sigterm else 'interrupted'}\n", out.stderr


def test_a_video_left_unread_stops_its_decoding_thread():
    """The frames decoded ahead in a thread: when the reader stops early, so does the thread (a thread still
    decoding as the process exits can crash it), its capture released."""
    _, frames = open_media(CLIP)
    next(frames)
    frames.close()
    assert not [t for t in threading.enumerate() if t.name == "jaxmocap-decode"]


def test_the_command_ends_its_process_with_its_code_and_all_its_output(tmp_path):
    """`command.entry` ends the process at once (no teardown) with the command's exit code, its output flushed
    first."""
    def entry(*args):
        return subprocess.run([sys.executable, "-c", "from jaxmocap.command import entry; entry()", *args],
                              capture_output=True, text=True, timeout=120)

    written = entry("model", "--out", str(tmp_path / "model.npz"))
    assert written.returncode == 0 and written.stdout == f"wrote the default body model to {tmp_path / 'model.npz'}\n"
    missing = entry("export", str(tmp_path / "missing.npz"), "--format", "bvh", "--out", str(tmp_path / "x.bvh"))
    assert missing.returncode == 2 and missing.stderr.count("\n") == 1 and "not found" in missing.stderr
