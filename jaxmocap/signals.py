"""Signal handlers for a block of code, the previous ones put back after it."""

import contextlib
import signal
import threading


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
