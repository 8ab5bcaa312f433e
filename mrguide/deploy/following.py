"""The following-error monitor of the deploy runtime: a cycle observer of the driver's control loop."""

from __future__ import annotations

import numpy as np

from mrguide.drivers.cobot_state import CycleSample


class FollowingMonitor:
    """Cycle observer: how far each measured joint is from the nearest of its setpoints sent in the last `depth`
    cycles, so servo lag, bus latency and late feedback are not counted as following error, while an arm that
    stopped following its commands is. Per joint, as a drive checks its own: each drive's feedback may be late
    by its own amount (a silent drive's feedback freezes; the feedback and heartbeat checks name it)."""

    def __init__(self, depth: int):
        self.recent: np.ndarray | None = None  # ring of the last `depth` setpoints
        self._distance: np.ndarray | None = None  # scratch of the ring's shape: no allocation per control cycle
        self.depth, self.count = depth, 0
        self.error = 0.0
        self.joint = 0  # the joint furthest from its nearest recent setpoint

    def __call__(self, sample: CycleSample) -> None:
        if sample.setpoint is not None:
            if self.recent is None:
                self.recent = np.tile(sample.setpoint, (self.depth, 1))
                self._distance = np.empty_like(self.recent)
            self.recent[self.count % self.depth] = sample.setpoint
            self.count += 1
        if self.recent is not None and self._distance is not None:
            np.subtract(self.recent, sample.positions, out=self._distance)
            per_joint = np.abs(self._distance, out=self._distance).min(axis=0)
            self.joint = int(per_joint.argmax())
            self.error = float(per_joint[self.joint])
