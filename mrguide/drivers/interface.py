"""`CobotInterface`: what the deploy runtime relies on of a cobot, and nothing more.

`drivers.cobot.Cobot` (CANopen) implements it; so can anything else that moves an arm one joint setpoint
per control period and works a vacuum gripper (a test double, another fieldbus). Connecting and
disconnecting are left to whoever owns the cobot: the runtime gets one that is connected and enabled.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Protocol, runtime_checkable

import numpy as np

from mrguide.drivers.cobot_state import CycleSample, DriverStats, JointState, VacuumState


@runtime_checkable
class CobotInterface(Protocol):
    """A connected cobot streaming joint setpoints, with a vacuum gripper and a per-cycle observer hook."""

    #: Control period (s): one setpoint is consumed per period.
    period: float

    @property
    def setpoint_queue_depth(self) -> int:
        """Setpoints buffered ahead of the arm; `stream` blocks when that many are waiting."""
        ...

    @property
    def feedback_tolerance_cycles(self) -> int:
        """Control cycles the measured joints may lag behind before the driver calls the feedback lost."""
        ...

    @property
    def setpoint(self) -> np.ndarray:
        """Last accepted joint setpoint (rad): where the next streamed setpoint must start from."""
        ...

    def enable(self, timeout: float | None = None) -> None:
        """Power the drives, holding the current position; then `stream` is allowed."""
        ...

    def stream(self, q: np.ndarray, timeout: float | None = None) -> None:
        """Queue the next joint setpoint (rad); blocks while the queue is full; raises DriverError on a fault
        (SetpointError for a setpoint outside the limits or too far from the previous one)."""
        ...

    def set_vacuum(self, on: bool, blow_off: bool = False) -> None:
        """Command the vacuum generator; accepted during a drive fault, so a held part stays held."""
        ...

    def stop(self) -> None:
        """Quick stop: the drives decelerate on their quick-stop ramp; never hangs, never raises."""
        ...

    def reset_faults(self, timeout: float | None = None) -> None:
        """Clear a latched fault (after the cause is gone); `enable` comes next."""
        ...

    def joint_state(self) -> JointState:
        """Latest measured joint positions and velocities."""
        ...

    def vacuum_state(self) -> VacuumState:
        """Latest vacuum level, part signal and the command being sent."""
        ...

    def stats(self) -> DriverStats:
        """Timing and traffic counters since connecting."""
        ...

    def add_cycle_observer(self, observer: Callable[[CycleSample], None]) -> None:
        """Call `observer` after every control cycle, in the control thread; an exception in it quick-stops (fails
        closed). Keep it short and never let go of the GIL in it (no I/O, no lock another thread holds, no NumPy call
        over 500 elements): the thread that takes the GIL then holds the cycle up to Python's 5 ms switch interval."""
        ...

    def remove_cycle_observer(self, observer: Callable[[CycleSample], None]) -> None: ...
