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
        self._item, self._full, self._closed = None, False, False
        self.dropped = 0

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
            if not self._changed.wait_for(lambda: self._full or self._closed, timeout):
                raise TimeoutError("no item")
            if not self._full:
                raise Closed
            item, self._item, self._full = self._item, None, False
            self._changed.notify_all()
            return item

    def close(self) -> None:
        with self._changed:
            self._closed = True
            self._changed.notify_all()
