"""The ``jaxmocap`` command's entry point (`entry`): its process's settings (`xla_options.configure_process`) before
anything loads NumPy's or SciPy's OpenBLAS or starts JAX, then the command line (`cli.main`). Importing the
package, or `cli`, changes nothing in a process.

Ctrl-C or SIGTERM at any moment ends the process with 130 or 143 and one line, never a traceback: while it starts
(an interrupt in a C extension's import comes out as an ImportError, from it or not: `signals.interrupt_of` and
the signals received) as while it runs (`cli.main` stops each command cleanly). Once the command has ended, both
are ignored while the process exits: Python's shutdown joins threads and runs exit callbacks, which an interrupt
would break. Then the process ends at once (`entry`): the command's files are written and closed by then, and the
teardown of the libraries' native threads at exit (JAX's, LiteRT's, OpenCV's) once crashed a process after its
work (a segmentation fault after "interrupted", once in 170 runs interrupted at random moments:
tests/stress_interrupts.py)."""

import os
import signal
import sys

from jaxmocap.signals import Terminated, interrupt_of, interrupts_kept


def entry() -> None:
    """The console script (and ``python -m jaxmocap.cli``): `main`, its output flushed, then the process's end with
    its exit code and no teardown."""
    code = main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def main(argv=None) -> int:
    """The command line ``argv`` (default: the process's) as `cli.main` runs it, with Ctrl-C and SIGTERM kept
    (the module docstring); its exit code."""
    received = []  # the signals that came: a C extension being imported can swallow the interrupt (printing it)
    # and raise an ImportError of its own, which nothing then ties to it

    def interrupt(signum, frame):
        received.append(signum)
        raise Terminated if signum == signal.SIGTERM else KeyboardInterrupt

    signal.signal(signal.SIGTERM, interrupt)  # the process's own: `cli.main` puts it back after its own
    if signal.getsignal(signal.SIGINT) is not signal.SIG_IGN:  # (a background job's stays ignored)
        signal.signal(signal.SIGINT, interrupt)
    try:
        with interrupts_kept():
            from jaxmocap.xla_options import configure_process

            configure_process()
            from jaxmocap.cli import main as cli_main

            code = cli_main(argv)
        _ended()  # the try's last step: an interrupt before it is caught below
    except BaseException as err:
        _ended()
        signum = interrupt_of(err) or (received[0] if received else None)
        if signum is None:
            raise
        print(f"jaxmocap: {'terminated' if signum == signal.SIGTERM else 'interrupted'}", file=sys.stderr)
        code = 128 + signum
    return code


def _ended() -> None:
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, signal.SIG_IGN)
