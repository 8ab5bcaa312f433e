"""Tracking error of streamed CSP setpoints, measured from the `Cobot`'s cycle samples."""

from __future__ import annotations

import numpy as np

from mrguide.drivers.cobot_state import CycleSample

#: Cycles from taking a setpoint off the queue to a position sample that reflects it: the RPDO sent in
#: cycle c is applied at SYNC c+1 and the position sampled at SYNC c+2 shows the motion toward it.
PIPELINE_CYCLES = 2


class TrackingRecorder:
    """Cycle observer: error between each measured joint position and the setpoint it answers (rad).

    Install with `cobot.add_cycle_observer(recorder)`. Only cycles while setpoints are being streamed
    (and the held setpoint afterwards) are compared; `reset()` starts a new measurement.
    """

    def __init__(self, dof: int, history: int = 256) -> None:
        self._dof = dof
        self._history = history
        self._held: dict[int, np.ndarray] = {}
        self._current: np.ndarray | None = None
        self.reset()

    def reset(self) -> None:
        self.max_error = np.zeros(self._dof)
        self.last_error = np.zeros(self._dof)
        self.samples = 0

    def __call__(self, sample: CycleSample) -> None:
        if sample.setpoint is not None:
            self._current = sample.setpoint
        if self._current is None:
            return
        self._held[sample.cycle] = self._current
        self._held.pop(sample.cycle - self._history, None)
        held = [self._held.get(int(s) - PIPELINE_CYCLES) for s in sample.feedback_sync]
        refs = [r for r in held if r is not None]
        if len(refs) < len(held):
            return
        reference = np.array([r[j] for j, r in enumerate(refs)])
        self.last_error = np.abs(sample.positions - reference)
        self.max_error = np.maximum(self.max_error, self.last_error)
        self.samples += 1
