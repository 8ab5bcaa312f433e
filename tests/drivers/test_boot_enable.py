"""Boot (NMT + SDO configuration) and enable six CiA 402 drives and the vacuum generator."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.drivers import BootError, Cobot, NotReadyError
from mrguide.drivers.cia402 import CSP_MODE, OPERATION_ENABLED, SWITCH_ON_DISABLED
from mrguide.drivers.mock import FirstOrderPlant, SimulatedCobot


def test_boot_configures_every_node_and_enable_reaches_operation_enabled(make_rig, robot):
    rig = make_rig()
    cobot, sim, config = rig.cobot, rig.sim, rig.config
    status = cobot.status()
    assert status.connected and not status.enabled and status.fault is None
    assert set(status.nmt_states.values()) == {"OPERATIONAL"}
    assert set(status.drive_states.values()) == {SWITCH_ON_DISABLED}
    for drive in sim.drives:  # what the master wrote by SDO, as the device holds it
        assert drive.operational
        assert drive.value((0x6060, 0)) == CSP_MODE and drive.value((0x6061, 0)) == CSP_MODE
        assert drive.value((0x1017, 0)) == config.timing.heartbeat_ms
        assert drive.value((0x1600, 1)) == 0x6040_0010 and drive.value((0x1600, 2)) == 0x607A_0020
        assert drive.value((0x1A00, 1)) == 0x6041_0010 and drive.value((0x1A00, 2)) == 0x6064_0020
        assert drive.value((0x1A01, 1)) == 0x606C_0020
        assert drive.value((0x605A, 0)) == config.drives.quick_stop_option
        assert drive.interpolation_period == pytest.approx(config.timing.control_period)
    assert sim.vacuum.value((0x2100, 0)) == round(config.vacuum.grip_threshold_kpa * 10)
    np.testing.assert_allclose(cobot.joint_state().positions, robot.q_home, atol=1e-6)
    assert cobot.vacuum_state().level_kpa == 0.0

    with pytest.raises(NotReadyError, match="enable"):
        cobot.stream(robot.q_home)
    cobot.enable()
    assert cobot.status().enabled
    assert set(cobot.joint_state().drive_states) == {OPERATION_ENABLED}
    assert all(d.state == OPERATION_ENABLED for d in sim.drives)
    syncs = sim.sync_count
    assert rig.wait_until(lambda: sim.sync_count >= syncs + 10)

    cobot.disconnect()
    assert not cobot.status().connected
    assert rig.wait_until(lambda: all(not s.operational for s in (*sim.drives, sim.vacuum)))
    assert all(d.state == SWITCH_ON_DISABLED for d in sim.drives)


def test_missing_node_is_named_at_boot(make_config, robot):
    config = make_config(boot_timeout=0.3)
    sim = SimulatedCobot(config, FirstOrderPlant(robot.q_home))
    sim.start()
    sim.faults.silence(5)
    try:
        with pytest.raises(BootError, match=r"node 5 \(elbow_joint\)") as info:
            Cobot(config, robot).connect()
        assert "node 4" not in str(info.value)
    finally:
        sim.stop()


def test_no_devices_at_all_is_a_clear_boot_error(make_config, robot):
    config = make_config(boot_timeout=0.2)
    cobot = Cobot(config, robot)
    with pytest.raises(BootError, match=r"no boot-up message from node 3 .* node 16"):
        cobot.connect()
    assert not cobot.status().connected
