"""The `Cobot`'s lock, which its control thread and its application calls share, and a lock-free mailbox.

The control thread holds the lock for microseconds per cycle. Application calls wait for it at most
`timeout` and then raise a DriverError naming a hung control thread instead of hanging with it. What must
not wait at all (a quick-stop request, a fault seen by the receive thread) is posted to a lock-free queue
that the control thread drains at the start of its next cycle.
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterator
from contextlib import contextmanager

from mrguide.drivers.errors import DriverError

#: Longest wait (s) of an application call for the driver lock: far above any legitimate hold, so a
#: longer one means the control thread hangs while holding it.
LOCK_TIMEOUT = 0.5


class DriverLock:
    """A re-entrant lock with bounded waits for application calls, plus a queue of posted requests.

    `with lock:` waits without bound (control thread); `with lock.bounded():` raises after `timeout`.
    A request is None (quick stop) or a DriverError (a fault to latch).
    """

    def __init__(self, timeout: float = LOCK_TIMEOUT) -> None:
        self.timeout = timeout
        self._lock = threading.RLock()
        self._requests: queue.SimpleQueue[DriverError | None] = queue.SimpleQueue()

    def __enter__(self) -> None:
        self._lock.acquire()

    def __exit__(self, *exc_info: object) -> None:
        self._lock.release()

    def acquire(self, timeout: float) -> bool:
        return self._lock.acquire(timeout=timeout)

    def release(self) -> None:
        self._lock.release()

    @contextmanager
    def bounded(self) -> Iterator[None]:
        """The lock for a call from the application: a DriverError after `timeout`, never a hang."""
        if not self._lock.acquire(timeout=self.timeout):
            raise DriverError(
                f"the control thread has held the driver lock for {self.timeout} s: it is hung "
                "(devices consuming the master's heartbeat disable themselves); reconnect"
            )
        try:
            yield
        finally:
            self._lock.release()

    def post(self, request: DriverError | None) -> None:
        """Hand a request to the control thread without taking the lock (any thread)."""
        self._requests.put(request)

    def drain(self) -> Iterator[DriverError | None]:
        """The requests posted so far, oldest first; iterate with the lock held."""
        while not self._requests.empty():
            yield self._requests.get_nowait()

    def discard_requests(self) -> None:
        """Forget requests left over from an earlier connection."""
        self._requests = queue.SimpleQueue()
