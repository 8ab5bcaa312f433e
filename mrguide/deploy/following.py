"""The following-error monitor of the deploy runtime: a cycle observer of the driver's control loop.

It runs in the control thread, so it must not let go of the GIL mid-cycle: NumPy releases it around any
ufunc loop over more than 500 elements (`NPY_BEGIN_THREADS_THRESHOLDED`), and a thread that took it then (the
simulated devices stepping their plant, the runtime computing setpoints) keeps the control thread waiting up
to Python's 5 ms switch interval, longer than the 4 ms control period. With a (250, 6) ring in one call the
observer did exactly that: in dry runs the cycle's work p99 was 2.5 ms against 0.9 ms since, and cycles after
the long ones started late (docs/performance.md, results/benchmarks/deploy-quiet-2026-12-04.txt). So every NumPy
call here works on at most `GIL_SAFE_ELEMENTS` elements.
"""

from __future__ import annotations

import math

import numpy as np

from mrguide.drivers.cobot_state import CycleSample

#: NumPy keeps the GIL through a ufunc loop over at most this many elements (its threading threshold).
GIL_SAFE_ELEMENTS = 500


class FollowingMonitor:
    """Cycle observer: how far each measured joint is from the nearest of its setpoints sent in the last `depth`
    cycles, so servo lag, bus latency and late feedback are not counted as following error, while an arm that
    stopped following its commands is. Per joint, as a drive checks its own: each drive's feedback may be late
    by its own amount (a silent drive's feedback freezes; the feedback and heartbeat checks name it)."""

    def __init__(self, depth: int):
        self.recent: np.ndarray | None = None  # per joint, a ring of its last `depth` setpoints: (joints, depth)
        self._distance = np.empty(min(depth, GIL_SAFE_ELEMENTS))  # scratch: no allocation per control cycle
        self.depth, self.count = depth, 0
        self.error = 0.0
        self.joint = 0  # the joint furthest from its nearest recent setpoint

    def __call__(self, sample: CycleSample) -> None:
        if sample.setpoint is not None:
            if self.recent is None:
                self.recent = np.repeat(np.asarray(sample.setpoint, dtype=float)[:, None], self.depth, axis=1)
            self.recent[:, self.count % self.depth] = sample.setpoint
            self.count += 1
        if self.recent is None:
            return
        per_joint = np.array([self._nearest(ring, float(q)) for ring, q in zip(self.recent, sample.positions)])
        self.joint = int(per_joint.argmax())  # the first NaN where a position is not a number
        self.error = float(per_joint[self.joint])

    def _nearest(self, ring: np.ndarray, position: float) -> float:
        """Distance from `position` to the nearest value of `ring`, in chunks the GIL is kept through."""
        if not math.isfinite(position):
            return float("nan")
        best = np.inf
        for start in range(0, len(ring), GIL_SAFE_ELEMENTS):
            chunk = ring[start : start + GIL_SAFE_ELEMENTS]
            d = self._distance[: len(chunk)]
            np.subtract(chunk, position, out=d)
            best = min(best, float(np.abs(d, out=d).min()))
        return best
