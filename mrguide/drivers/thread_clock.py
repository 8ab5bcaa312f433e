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

import operator
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TypeVar

SCHEDSTAT = "/proc/thread-self/schedstat"

N = TypeVar("N", int, float)


def if_known(op: Callable[[N, N], N], a: N | None, b: N | None) -> N | None:
    """`op(a, b)`, or None when either counter is unknown (no /proc)."""
    return None if a is None or b is None else op(a, b)


@dataclass(frozen=True)
class ThreadReading:
    """One thread's clocks at one moment (s)."""

    wall: float
    cpu: float
    #: Time spent runnable on a run queue since the thread started; None without /proc.
    runq: float | None
    #: How many times the thread has been put on a CPU since it started; None without /proc.
    slices: int | None = None


@dataclass(frozen=True)
class Gap:
    """The time between two readings of a thread, by where it went (s)."""

    wall: float
    cpu: float
    slept: float
    runq: float | None
    #: Times the thread was put on a CPU in the gap: once per wake-up from a sleep or a block, once more per
    #: preemption. A gap that skipped deadlines off a CPU in a single stretch after its planned sleep has one (the
    #: wake-up came late: a timer the host delayed); blocked again after waking (the GIL held), it has more.
    slices: int | None = None

    @classmethod
    def between(cls, earlier: ThreadReading, later: ThreadReading, slept: float) -> Gap:
        runq = if_known(operator.sub, later.runq, earlier.runq)
        slices = if_known(operator.sub, later.slices, earlier.slices)
        return cls(later.wall - earlier.wall, later.cpu - earlier.cpu, slept, runq, slices)

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
        wall, cpu = time.monotonic(), time.thread_time()
        runq, slices = self._schedstat()
        return ThreadReading(wall, cpu, runq, slices)

    def _schedstat(self) -> tuple[float | None, int | None]:
        """The run-queue wait (s) and the times put on a CPU, from the schedstat line `run_ns wait_ns timeslices`."""
        if self._fd is None:
            return None, None
        try:
            fields = os.pread(self._fd, 128, 0).split()
            return int(fields[1]) / 1e9, int(fields[2])
        except (OSError, IndexError, ValueError):
            return None, None

    def close(self) -> None:
        if self._fd is not None:
            os.close(self._fd)
            self._fd = None
