"""A cycle observer that raises fails closed: the cobot latches a fault and quick-stops.

Observers are safety checks too (the deploy runtime's following-error monitor is one), so an exception
in one must stop the arm rather than silently switch the check off.
"""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.drivers import DriverError
from mrguide.drivers.cia402 import OPERATION_ENABLED


def test_an_observer_exception_latches_a_fault_and_quick_stops(rig):
    cobot = rig.cobot
    calls = []

    def broken_monitor(sample) -> None:
        calls.append(sample.cycle)
        if len(calls) == 10:
            raise ZeroDivisionError("monitor bug")

    cobot.add_cycle_observer(broken_monitor)
    q = cobot.setpoint
    with pytest.raises(DriverError, match=r"broken_monitor.*ZeroDivisionError") as info:
        for _ in range(500):
            q = q + np.full(6, 0.2 * cobot.period)
            cobot.stream(q)
    assert cobot.status().fault is info.value
    assert rig.wait_until(lambda: all(s != OPERATION_ENABLED for s in cobot.status().drive_states.values()))
