"""A one-item hand-off between two threads: the live path's only queue, so nothing waits in it but the newest."""

import threading


class Closed(Exception):
    """The mailbox was closed and holds nothing more."""


class Mailbox:
    """Holds at most one item. `put` either replaces an item not yet taken (counted in ``dropped``) or, with
    ``wait``, waits until it has been taken (lossless); `get` waits for an item. After `close`, `get` returns what
    is left, then raises `Closed`; `put` drops its item."""

    def __init__(self):
        self._changed = threading.Condition()
        self._item, self._full, self._closed, self._waiting = None, False, False, 0
        self.dropped = 0

    def asked(self, timeout: float) -> bool:
        """Whether someone waits in `get` for an item, waiting at most ``timeout`` seconds for one to (False at
        once when closed): what a producer that makes an item only when it is taken waits on."""
        with self._changed:
            self._changed.wait_for(lambda: (self._waiting > 0 and not self._full) or self._closed, max(timeout, 0.0))
            return self._waiting > 0 and not self._full and not self._closed

    def put(self, item, wait: bool = False) -> None:
        with self._changed:
            if wait:
                self._changed.wait_for(lambda: not self._full or self._closed)
            if self._closed:
                return
            self.dropped += self._full
            self._item, self._full = item, True
            self._changed.notify_all()

    def get(self, timeout: float | None = None):
        """The item, waiting at most ``timeout`` seconds (then `TimeoutError`)."""
        with self._changed:
            self._waiting += 1
            self._changed.notify_all()
            try:
                if not self._changed.wait_for(lambda: self._full or self._closed, timeout):
                    raise TimeoutError("no item")
            finally:
                self._waiting -= 1
            if not self._full:
                raise Closed
            item, self._item, self._full = self._item, None, False
            self._changed.notify_all()
            return item

    def close(self) -> None:
        with self._changed:
            self._closed = True
            self._changed.notify_all()
