"""Cycle timing: absolute deadlines on a monotonic clock, and statistics of how late each cycle started.

Deadline k is `t0 + k * period`, computed from the start time, so sleep overshoot never accumulates into
drift. A cycle that starts more than one period late skips the deadlines it missed (no burst of catch-up
SYNCs) and counts them as missed cycles.
"""

from __future__ import annotations

import operator
import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from mrguide.drivers.thread_clock import Gap, if_known


@dataclass(frozen=True)
class Tick:
    """One cycle: its number (skipped deadlines included), when it was due, how many were skipped, and how long
    the timer slept before it (s)."""

    index: int
    deadline: float
    skipped: int
    slept: float = 0.0


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
        skipped, slept = 0, 0.0
        if now < deadline:
            slept = deadline - now
            self._sleep(slept)
            now = self._clock()  # a wake-up more than a period late skips too, in this cycle's gap
        if now - deadline >= self.period:
            skipped = int((now - deadline) // self.period)
            k += skipped
            deadline = self._t0 + k * self.period
        self._k = k
        return Tick(k, deadline, skipped, slept)


#: How many of the latest gaps `MissAnatomy.recent` keeps.
RECENT_GAPS = 64


@dataclass(frozen=True)
class MissAnatomy:
    """The gaps between two cycle starts with deadlines skipped between them, summed by where the control thread's
    time went (s; see `thread_clock`). The run-queue wait and the rest off a CPU are None when a gap's were unknown."""

    gaps: int = 0
    wall_s: float = 0.0
    cpu_s: float = 0.0
    slept_s: float = 0.0
    runq_s: float | None = 0.0
    off_cpu_s: float | None = 0.0
    slices: int | None = 0
    #: The control thread's own garbage collections in those gaps, and their time (s).
    collections: int = 0
    collecting_s: float = 0.0
    #: The latest RECENT_GAPS gaps, each as (when it ended on `time.monotonic()`, its length in s, deadlines
    #: skipped): one clock for every process of the machine, so another process's late wake-ups can be matched.
    recent: tuple[tuple[float, float, int], ...] = ()

    def add(self, gap: Gap, skipped: int = 1) -> MissAnatomy:
        return replace(
            self,
            recent=(*self.recent[1 - RECENT_GAPS :], (gap.ended, gap.wall, skipped)),
            gaps=self.gaps + 1,
            wall_s=self.wall_s + gap.wall,
            cpu_s=self.cpu_s + gap.cpu,
            slept_s=self.slept_s + gap.slept,
            runq_s=if_known(operator.add, self.runq_s, gap.runq),
            off_cpu_s=if_known(operator.add, self.off_cpu_s, gap.off_cpu),
            slices=if_known(operator.add, self.slices, gap.slices),
            collections=self.collections + gap.collections,
            collecting_s=self.collecting_s + gap.collecting,
        )

    def since(self, earlier: MissAnatomy) -> dict[str, Any]:
        """The gaps added after `earlier` (a snapshot of the same counters), by field, for a run log's record;
        `miss_at` lists the latest RECENT_GAPS of them as `recent` holds them."""
        added = min(self.gaps - earlier.gaps, len(self.recent))
        return {
            "miss_gaps": self.gaps - earlier.gaps,
            "miss_wall_s": self.wall_s - earlier.wall_s,
            "miss_cpu_s": self.cpu_s - earlier.cpu_s,
            "miss_slept_s": self.slept_s - earlier.slept_s,
            "miss_runq_s": if_known(operator.sub, self.runq_s, earlier.runq_s),
            "miss_off_cpu_s": if_known(operator.sub, self.off_cpu_s, earlier.off_cpu_s),
            "miss_slices": if_known(operator.sub, self.slices, earlier.slices),
            "miss_collections": self.collections - earlier.collections,
            "miss_collecting_s": self.collecting_s - earlier.collecting_s,
            "miss_at": [list(r) for r in self.recent[len(self.recent) - added :]],
        }


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
    misses: MissAnatomy = MissAnatomy()


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
        self._misses = MissAnatomy()

    def record(self, lateness: float, skipped: int) -> None:
        self._lateness[self._n % len(self._lateness)] = lateness
        self._n += 1
        self._missed += skipped

    def record_work(self, duration: float) -> None:
        self._work[self._n_work % len(self._work)] = duration
        self._n_work += 1
        self._overruns += duration > self._period

    def record_miss(self, gap: Gap, skipped: int) -> None:
        """The gap from the previous cycle's start to this one's, for a cycle that skipped `skipped` deadlines."""
        self._misses = self._misses.add(gap, skipped)

    def summary(self) -> CycleSummary:
        n = min(self._n, len(self._lateness))
        if n == 0:
            return CycleSummary(0, self._missed, 0.0, 0.0, 0.0, overruns=self._overruns, misses=self._misses)
        p50, p99 = np.percentile(self._lateness[:n], [50, 99])
        lateness_max = float(self._lateness[:n].max())
        w = self._work[: min(self._n_work, len(self._work))]
        work_p99, work_max = (float(np.percentile(w, 99)), float(w.max())) if len(w) else (0.0, 0.0)
        return CycleSummary(
            self._n,
            self._missed,
            float(p50),
            float(p99),
            lateness_max,
            work_p99,
            work_max,
            self._overruns,
            self._misses,
        )
