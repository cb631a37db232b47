"""Signal handlers for a block of code, the previous ones put back after it; Ctrl-C that is never dropped; work
that Ctrl-C (or Ray's cancel) stops whatever the process inherited."""

import _thread
import contextlib
import signal
import sys
import threading


class Terminated(KeyboardInterrupt):
    """The KeyboardInterrupt a SIGTERM raises where a command stops on it as on Ctrl-C (`jaxmocap.cli`)."""


@contextlib.contextmanager
def handling(handler, *signums: signal.Signals):
    """``handler`` for the signals ``signums`` inside the block (None: they keep their handlers, whatever the
    block sets); after it, the handlers they had before. In the main thread only: elsewhere signals do not arrive
    and Python sets no handler."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {s: signal.getsignal(s) for s in signums}
    if handler is not None:
        for s in signums:
            signal.signal(s, handler)
    try:
        yield
    finally:
        for s, old in previous.items():
            if old is not None:  # (None: a handler Python did not set, which it cannot put back)
                signal.signal(s, old)


def interrupt_of(err: BaseException) -> int | None:
    """The signal an exception stands for: SIGTERM for `Terminated`, SIGINT for another KeyboardInterrupt, also
    where one caused the exception or was being handled as it was raised (Ctrl-C in a C extension's import comes
    out as an ImportError from it); None for others."""
    seen = set()
    while err is not None and id(err) not in seen:
        if isinstance(err, KeyboardInterrupt):
            return signal.SIGTERM if isinstance(err, Terminated) else signal.SIGINT
        seen.add(id(err))
        err = err.__cause__ or err.__context__
    return None


RESIGNAL_SECONDS = 0.01  # after a dropped interrupt, when it is signalled again


@contextlib.contextmanager
def interrupts_kept():
    """Inside, a KeyboardInterrupt raised where Python cannot pass it on is raised again. A signal's handler runs
    at whatever Python code the main thread runs next, which may be a garbage collector's callback (JAX's, after
    each collection) or a finaliser: Python prints "Exception ignored in ..." and goes on, and Ctrl-C, SIGTERM or
    Ray's cancel (a SIGINT to the task's thread) is lost while the work runs to its end. Here such an interrupt is
    signalled again `RESIGNAL_SECONDS` later, from another thread (`Terminated` as SIGTERM, others as SIGINT), so
    that its handler runs once more, in the code the main thread has gone back to. In the main thread only, as
    `handling`."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous, timers = sys.unraisablehook, []

    def hook(unraisable):
        if issubclass(unraisable.exc_type, KeyboardInterrupt):
            signum = signal.SIGTERM if issubclass(unraisable.exc_type, Terminated) else signal.SIGINT
            timer = threading.Timer(RESIGNAL_SECONDS, _thread.interrupt_main, (signum,))
            timer.daemon = True
            timer.start()
            timers.append(timer)
        else:
            previous(unraisable)

    sys.unraisablehook = hook
    try:
        yield
    finally:
        sys.unraisablehook = previous
        for timer in timers:  # the block is over: nothing left to stop
            timer.cancel()


@contextlib.contextmanager
def cancellable():
    """Inside, Ctrl-C raises KeyboardInterrupt (Python's own handler, even where the process inherited SIGINT
    ignored, as everything started from a background job or ``nohup`` does, Ray's workers included: Ray cancels a
    running task by a SIGINT to it) and is never dropped (`interrupts_kept`)."""
    with handling(signal.default_int_handler, signal.SIGINT), interrupts_kept():
        yield
