"""CiA 402 power state machine: master controlwords, device transitions, and the two together."""

from __future__ import annotations

import pytest

from mrguide.drivers.cia402 import OPERATION_ENABLED, PowerCommand, controlword_for, decode_state, interpolation_period
from mrguide.drivers.errors import BootError
from mrguide.drivers.mock.drive_sim import _STATE_BITS, SW_REMOTE, SW_VOLTAGE_ENABLED, next_power_state


@pytest.mark.parametrize("state", list(_STATE_BITS))
def test_statusword_of_each_device_state_decodes_to_it(state):
    assert decode_state(_STATE_BITS[state] | SW_REMOTE | SW_VOLTAGE_ENABLED * (state != "FAULT")) == state


def _drive(state: str, command: PowerCommand, option: int = 2, cycles: int = 6) -> list[str]:
    """Run master and device state machines against each other; returns the state after each cycle."""
    previous, seen = 0, []
    for _ in range(cycles):
        cw = controlword_for(state, command, previous)
        state = next_power_state(state, cw, previous, option)
        previous = cw
        seen.append(state)
    return seen


def test_enable_walks_the_402_path():
    seen = _drive("SWITCH ON DISABLED", PowerCommand.ENABLE)
    assert seen[:3] == ["READY TO SWITCH ON", "SWITCHED ON", OPERATION_ENABLED]
    assert seen[-1] == OPERATION_ENABLED


def test_quick_stop_and_disable():
    assert _drive(OPERATION_ENABLED, PowerCommand.QUICK_STOP, cycles=1) == ["QUICK STOP ACTIVE"]
    assert _drive(OPERATION_ENABLED, PowerCommand.DISABLE, cycles=1) == ["SWITCH ON DISABLED"]


def test_enable_never_resets_a_fault():
    assert set(_drive("FAULT", PowerCommand.ENABLE)) == {"FAULT"}


def test_fault_reset_needs_a_rising_edge():
    assert _drive("FAULT", PowerCommand.FAULT_RESET, cycles=1) == ["SWITCH ON DISABLED"]
    # a drive whose fault persists sees bit 7 toggled, so each retry is a new rising edge
    assert [controlword_for("FAULT", PowerCommand.FAULT_RESET, p) for p in (0x80, 0x00)] == [0x00, 0x80]
    assert next_power_state("FAULT", 0x80, 0x80, 2) == "FAULT"


def test_return_from_quick_stop_depends_on_option_code():
    assert next_power_state("QUICK STOP ACTIVE", 0x0F, 0x02, 6) == OPERATION_ENABLED
    assert next_power_state("QUICK STOP ACTIVE", 0x0F, 0x02, 2) == "QUICK STOP ACTIVE"


def test_interpolation_period_object():
    assert interpolation_period(0.004) == (4, -3)
    assert interpolation_period(0.0005) == (5, -4)
    with pytest.raises(BootError):
        interpolation_period(0.0041234567)
