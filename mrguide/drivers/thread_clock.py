"""Where a thread's time went: on a CPU, waiting for one, or neither — for telling a missed control cycle's causes
apart from inside the control thread.

Between two readings of the same thread, `Gap` splits the wall time into the thread's CPU time
(`time.thread_time`), its wait on the kernel's run queue (runnable but no core free: other threads and processes of
the machine; the second field of /proc/thread-self/schedstat) and the time it asked to sleep; the rest it spent off
a CPU without asking: blocked on the GIL (another thread of the interpreter holding it), on I/O (a CAN send), or,
on a virtual machine whose guest does not charge steal to the thread, its virtual CPU taken by the host. Linux
only: elsewhere the run-queue wait is unknown and so is the rest.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

SCHEDSTAT = "/proc/thread-self/schedstat"


@dataclass(frozen=True)
class ThreadReading:
    """One thread's clocks at one moment (s)."""

    wall: float
    cpu: float
    #: Time spent runnable on a run queue since the thread started; None without /proc.
    runq: float | None


@dataclass(frozen=True)
class Gap:
    """The time between two readings of a thread, by where it went (s)."""

    wall: float
    cpu: float
    slept: float
    runq: float | None

    @classmethod
    def between(cls, earlier: ThreadReading, later: ThreadReading, slept: float) -> Gap:
        runq = None if later.runq is None or earlier.runq is None else later.runq - earlier.runq
        return cls(later.wall - earlier.wall, later.cpu - earlier.cpu, slept, runq)

    @property
    def off_cpu(self) -> float | None:
        """Off a CPU without asking to sleep: the GIL, I/O, or the host (see the module docstring)."""
        return None if self.runq is None else max(0.0, self.wall - self.cpu - self.runq - self.slept)


class ThreadClock:
    """Reads the clocks of the thread that created it (create it in the thread to be measured; `close` it there)."""

    def __init__(self) -> None:
        try:
            self._fd: int | None = os.open(SCHEDSTAT, os.O_RDONLY)
        except OSError:
            self._fd = None

    def read(self) -> ThreadReading:
        return ThreadReading(time.monotonic(), time.thread_time(), self._runq())

    def _runq(self) -> float | None:
        if self._fd is None:
            return None
        try:
            return int(os.pread(self._fd, 128, 0).split()[1]) / 1e9  # run_ns wait_ns timeslices
        except (OSError, IndexError, ValueError):
            return None

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
