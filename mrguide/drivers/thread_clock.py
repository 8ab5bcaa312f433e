"""Where a thread's time went: on a CPU, waiting for one, or neither — for telling a missed control cycle's causes
apart from inside the control thread.

Between two readings of the same thread, `Gap` splits the wall time into the thread's CPU time
(`time.thread_time`), its wait on the kernel's run queue (runnable but no core free: other threads and processes of
the machine; the second field of /proc/thread-self/schedstat) and the time it asked to sleep; the rest it spent off
a CPU without asking: blocked on the GIL (another thread of the interpreter holding it), on I/O (a CAN send), or,
on a virtual machine whose guest does not charge steal to the thread, its virtual CPU taken by the host. Linux
only: elsewhere the run-queue wait is unknown and so is the rest.

A thread's own garbage collections are counted apart (a `gc` callback, installed while a `ThreadClock` is open): the
interpreter collects in whichever thread's allocation crossed a generation's threshold, the control thread included,
with the GIL held, so a young collection that meets many objects is time on a CPU that the cycle's own work did not
ask for.
"""

from __future__ import annotations

import gc
import operator
import os
import threading
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
    #: Garbage collections this thread ran while a ThreadClock was open, and their wall time (s).
    collections: int = 0
    collecting: float = 0.0


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
    #: The thread's own garbage collections in the gap, of any generation, and their wall time (part of the rest).
    collections: int = 0
    collecting: float = 0.0
    #: When the gap ended (`time.monotonic()`, s).
    ended: float = 0.0

    @classmethod
    def between(cls, earlier: ThreadReading, later: ThreadReading, slept: float) -> Gap:
        runq = if_known(operator.sub, later.runq, earlier.runq)
        slices = if_known(operator.sub, later.slices, earlier.slices)
        return cls(
            later.wall - earlier.wall,
            later.cpu - earlier.cpu,
            slept,
            runq,
            slices,
            later.collections - earlier.collections,
            later.collecting - earlier.collecting,
            later.wall,
        )

    @property
    def off_cpu(self) -> float | None:
        """Off a CPU without asking to sleep: the GIL, I/O, or the host (see the module docstring)."""
        return None if self.runq is None else max(0.0, self.wall - self.cpu - self.runq - self.slept)


class _Collections(threading.local):
    """Per thread: the garbage collections it ran and their wall time (s), while the callback is installed."""

    count = 0
    seconds = 0.0
    started: float | None = None


_collections = _Collections()
_clocks_open = 0  # open ThreadClocks; the callback is installed while there is one
_clocks_lock = threading.Lock()


def _on_collection(phase: str, info: dict) -> None:
    """gc callback: runs in the thread that collects, at the start and the stop of every collection."""
    own = _collections
    if phase == "start":
        own.started = time.monotonic()
    elif own.started is not None:
        own.count += 1
        own.seconds += time.monotonic() - own.started
        own.started = None


def _count_collections(delta: int) -> None:
    """Open (+1) or close (-1) a ThreadClock: the first installs the gc callback, the last removes it."""
    global _clocks_open
    with _clocks_lock:
        _clocks_open += delta
        if _clocks_open == 1 and delta > 0:
            gc.callbacks.append(_on_collection)
        elif _clocks_open == 0 and _on_collection in gc.callbacks:
            gc.callbacks.remove(_on_collection)


class ThreadClock:
    """Reads the clocks of the thread that created it (create it in the thread to be measured; `close` it there)."""

    def __init__(self) -> None:
        try:
            self._fd: int | None = os.open(SCHEDSTAT, os.O_RDONLY)
        except OSError:
            self._fd = None
        self._open = True
        _count_collections(+1)

    def read(self) -> ThreadReading:
        wall, cpu = time.monotonic(), time.thread_time()
        runq, slices = self._schedstat()
        return ThreadReading(wall, cpu, runq, slices, _collections.count, _collections.seconds)

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
        if self._open:
            self._open = False
            _count_collections(-1)
