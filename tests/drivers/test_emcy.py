"""EMCY: drive fault -> FAULT state, motion stopped, quick stop for the others, fault reset path."""

from __future__ import annotations

import time

import numpy as np
import pytest

from mrguide.drivers import DeviceFaultError, DriverError
from mrguide.drivers.cia402 import OPERATION_ENABLED, SWITCH_ON_DISABLED
from mrguide.drivers.mock import FirstOrderParams
from mrguide.drivers.mock.drive_sim import EMCY_FOLLOWING_ERROR


def test_drive_fault_stops_motion_and_fault_reset_recovers(rig):
    cobot, sim = rig.cobot, rig.sim
    q = cobot.setpoint
    step = np.full(6, 0.5 * cobot.period)
    with pytest.raises(DeviceFaultError) as info:
        for k in range(2000):
            q = q + step
            cobot.stream(q)
            if k == 30:
                sim.inject_drive_fault(4, 0x2310)
    error = info.value
    assert error.node_id == 4 and error.name == "shoulder_lift_joint" and error.emcy_code == 0x2310
    assert "0x2310" in str(error)
    assert rig.wait_until(lambda: cobot.status().drive_states["shoulder_lift_joint"] == "FAULT")
    assert rig.wait_until(
        lambda: all(
            s == SWITCH_ON_DISABLED for n, s in cobot.status().drive_states.items() if n != "shoulder_lift_joint"
        )
    )
    p1 = cobot.joint_state().positions
    time.sleep(0.1)
    assert np.max(np.abs(cobot.joint_state().positions - p1)) < 1e-5  # the arm stands still
    with pytest.raises(DeviceFaultError):
        cobot.enable()  # no enable over a latched fault
    with pytest.raises(DeviceFaultError):
        cobot.check()

    cobot.reset_faults()
    status = cobot.status()
    assert status.fault is None
    assert set(status.drive_states.values()) == {SWITCH_ON_DISABLED}
    assert sim.drives[1].value((0x603F, 0)) == 0  # error code cleared on the device
    cobot.enable()
    q = cobot.setpoint
    for _ in range(25):
        q = q - step
        cobot.stream(q)
    assert set(cobot.joint_state().drive_states) == {OPERATION_ENABLED}
    assert cobot.stats().emcy_received >= 2  # the fault and the device's "error reset" EMCY


def test_following_error_on_the_device_faults_it(make_rig):
    rig = make_rig(plant_params=FirstOrderParams(joint_time_constant=0.5))  # a sluggish joint
    cobot = rig.cobot
    cobot.enable()
    q = cobot.setpoint
    with pytest.raises(DriverError) as info:
        for _ in range(500):
            q = q + np.full(6, 1.4 * cobot.period)
            cobot.stream(q)
    assert isinstance(info.value, DeviceFaultError)
    assert info.value.emcy_code == EMCY_FOLLOWING_ERROR
