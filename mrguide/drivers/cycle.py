"""Cycle timing: absolute deadlines on a monotonic clock, and statistics of how late each cycle started.

Deadline k is `t0 + k * period`, computed from the start time, so sleep overshoot never accumulates into
drift. A cycle that starts more than one period late skips the deadlines it missed (no burst of catch-up
SYNCs) and counts them as missed cycles.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Tick:
    """One cycle: its number (skipped deadlines included), when it was due, and how many were skipped."""

    index: int
    deadline: float
    skipped: int


class CycleTimer:
    """Waits for successive absolute deadlines `t0 + k * period` of a monotonic clock."""

    def __init__(
        self, period: float, clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep
    ) -> None:
        if period <= 0:
            raise ValueError(f"cycle period must be > 0, got {period}")
        self.period = period
        self._clock = clock
        self._sleep = sleep
        self._t0 = 0.0
        self._k = 0

    def start(self) -> None:
        """Take the current time as t0; the first deadline is one period later."""
        self._t0 = self._clock()
        self._k = 0

    def wait(self) -> Tick:
        """Sleep until the next deadline (or return at once if it has passed) and describe the cycle."""
        k = self._k + 1
        deadline = self._t0 + k * self.period
        now = self._clock()
        skipped = 0
        if now < deadline:
            self._sleep(deadline - now)
        elif now - deadline >= self.period:
            skipped = int((now - deadline) // self.period)
            k += skipped
            deadline = self._t0 + k * self.period
        self._k = k
        return Tick(k, deadline, skipped)


@dataclass(frozen=True)
class CycleSummary:
    """Lateness of cycle starts (s) and counts; percentiles over the most recent `capacity` cycles."""

    cycles: int
    missed: int
    lateness_p50: float
    lateness_p99: float
    lateness_max: float
    #: How long a cycle's work took (s), from its start to the end of its observers: past one period, the next
    #: cycle starts late.
    work_p99: float = 0.0
    work_max: float = 0.0
    #: Cycles whose work took longer than the period (each makes the next start late, or skips it).
    overruns: int = 0


class CycleStats:
    """Records each cycle's lateness (actual start minus deadline) and its work's duration in ring buffers, and
    counts the cycles whose work took longer than `period`."""

    def __init__(self, capacity: int = 1 << 17, period: float = float("inf")) -> None:
        self._lateness = np.zeros(capacity)
        self._work = np.zeros(capacity)
        self._period = period
        self._n = 0
        self._n_work = 0
        self._missed = 0
        self._overruns = 0

    def record(self, lateness: float, skipped: int) -> None:
        self._lateness[self._n % len(self._lateness)] = lateness
        self._n += 1
        self._missed += skipped

    def record_work(self, duration: float) -> None:
        self._work[self._n_work % len(self._work)] = duration
        self._n_work += 1
        self._overruns += duration > self._period

    def summary(self) -> CycleSummary:
        n = min(self._n, len(self._lateness))
        if n == 0:
            return CycleSummary(0, self._missed, 0.0, 0.0, 0.0, overruns=self._overruns)
        p50, p99 = np.percentile(self._lateness[:n], [50, 99])
        lateness_max = float(self._lateness[:n].max())
        w = self._work[: min(self._n_work, len(self._work))]
        work_p99, work_max = (float(np.percentile(w, 99)), float(w.max())) if len(w) else (0.0, 0.0)
        return CycleSummary(
            self._n, self._missed, float(p50), float(p99), lateness_max, work_p99, work_max, self._overruns
        )
