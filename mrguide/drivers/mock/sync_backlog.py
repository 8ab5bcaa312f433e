"""How far the simulated devices' world runs behind the wall clock: a dry run that is not a real-time one.

The simulated devices step their plant one control period per SYNC, so the world's time is the SYNCs handled times
the period. On a real cell the drives' world is the physical one and never falls behind; a simulated cell on a busy
PC (its process or thread waiting for a CPU, or for the GIL) handles SYNCs late and then in a burst, and meanwhile the
arm the controller reads stands where it stood a moment ago. An episode played that way is not a measurement of the
policy on a cell.

The lag of SYNC k is `now − t₀ − k · period`; the backlog over an interval is how far the lag rose above its lowest
within it (a SYNC the master itself skipped adds one period, counted apart in its missed control cycles).
"""

from __future__ import annotations

import math
import threading


class SyncBacklog:
    """`tick()` per SYNC handled, from the thread that handles it; `take()` from any thread."""

    def __init__(self, period: float):
        self.period = period
        self._lock = threading.Lock()
        self._t0: float | None = None
        self._count = 0
        self._low, self._high = math.inf, -math.inf

    def tick(self, now: float) -> None:
        """A SYNC handled at monotonic time `now` (s)."""
        with self._lock:
            if self._t0 is None:
                self._t0 = now
            lag = now - self._t0 - self._count * self.period
            self._count += 1
            self._low, self._high = min(self._low, lag), max(self._high, lag)

    def take(self) -> float:
        """The largest backlog (s) since the last `take`: the lag's rise above its lowest; 0 without a SYNC."""
        with self._lock:
            out = self._high - self._low if self._high >= self._low else 0.0
            self._low, self._high = math.inf, -math.inf
        return out
