"""The master's heartbeat: produced by the control thread, consumed by every device (0x1016).

A hung control thread (or a dead PC) must disable the drives without the master's help, keep the vacuum
as commanded (a held part must not drop), and a planned disconnect must not look like a master loss.
"""

from __future__ import annotations

import struct
import threading
import time
from dataclasses import replace

import canopen
import numpy as np
import pytest

from mrguide.drivers import Cobot, DeviceFaultError
from mrguide.drivers.config import MasterConfig, eds_path
from mrguide.drivers.heartbeat import HEARTBEAT_ERROR, consumer_heartbeat_entry
from mrguide.drivers.mock import FirstOrderPlant, SimulatedCobot
from mrguide.drivers.mock.drive_sim import OPERATION_ENABLED, SWITCH_ON_DISABLED
from mrguide.drivers.objects import CONSUMER_HEARTBEAT_TIME

HB = 0.05  # heartbeat period of the test rigs (s); consumer time: config.timing.heartbeat_timeout
MASTER = 127


def _emcy_codes(tap, node_id: int) -> list[int]:
    return [struct.unpack_from("<H", m.data)[0] for m in tap.with_id(0x080 + node_id) if len(m.data) == 8]


def test_every_device_consumes_the_master_heartbeat_sent_every_period(rig, tap_on):
    tap = tap_on(rig.config.bus.channel)
    for slave in (*rig.sim.drives, rig.sim.vacuum):
        assert slave.value((CONSUMER_HEARTBEAT_TIME, 1)) == consumer_heartbeat_entry(
            MASTER, rig.config.timing.heartbeat_timeout_ms
        )
    time.sleep(20 * HB)
    beats = tap.with_id(0x700 + MASTER)
    assert beats and all(bytes(m.data) == b"\x05" for m in beats)  # state OPERATIONAL
    intervals = np.diff([m.timestamp for m in beats])
    assert np.median(intervals) == pytest.approx(HB, rel=0.2)
    assert not any(HEARTBEAT_ERROR in _emcy_codes(tap, n) for n in rig.config.node_ids)


def test_hung_control_thread_disables_the_drives_and_keeps_the_vacuum(rig, tap_on):
    cobot, sim = rig.cobot, rig.sim
    tap = tap_on(rig.config.bus.channel)
    cobot.set_vacuum(True)
    q = cobot.setpoint
    for _ in range(25):
        q = q + np.full(6, 0.2 * cobot.period)
        cobot.stream(q)
    assert rig.wait_until(lambda: sim.vacuum.commands()[0])
    release = threading.Event()
    cycle = cobot._loop.cycle
    cobot._loop.cycle = lambda tick: release.wait()  # the control thread hangs: no SYNC, no heartbeat
    hung_at = time.monotonic()
    try:
        assert rig.wait_until(
            lambda: (
                all(d.state == SWITCH_ON_DISABLED for d in sim.drives)
                and not any(slave.operational for slave in (*sim.drives, sim.vacuum))
            ),
            timeout=1.0,
        )
        reacted_after = time.monotonic() - hung_at
        # consumer time + the last beat's age + scheduling
        assert reacted_after <= rig.config.timing.heartbeat_timeout + HB + 0.1
        assert rig.wait_until(lambda: all(HEARTBEAT_ERROR in _emcy_codes(tap, n) for n in rig.config.node_ids))
        assert sim.vacuum.commands() == (True, False)  # the held part stays held
        # the master's receive thread (alive meanwhile) has taken the EMCYs and posted them as faults
        assert rig.wait_until(lambda: cobot.stats().emcy_received >= len(rig.config.node_ids))
    finally:
        cobot._loop.cycle = cycle
        release.set()
    assert rig.wait_until(lambda: cobot.status().fault is not None)
    # the first fault latched once the thread is back: a device's heartbeat-consumer EMCY (0x8130), not just
    # anything (a lost node, a drive that left OPERATION ENABLED come after it)
    fault = cobot.status().fault
    assert isinstance(fault, DeviceFaultError) and fault.emcy_code == HEARTBEAT_ERROR, repr(fault)
    assert fault.node_id in rig.config.node_ids and "EMCY 0x8130" in str(fault)
    cobot.disconnect()  # recovery: reconnect boots the devices again (NMT reset communication)
    cobot.connect()
    cobot.enable()
    assert all(d.state == OPERATION_ENABLED for d in sim.drives)


def test_planned_disconnect_is_not_a_master_loss(make_rig, tap_on):
    rig = make_rig()
    tap = tap_on(rig.config.bus.channel)
    rig.cobot.enable()
    rig.cobot.disconnect()
    for slave in (*rig.sim.drives, rig.sim.vacuum):
        assert slave.value((CONSUMER_HEARTBEAT_TIME, 1)) == 0
    time.sleep(2 * rig.config.timing.heartbeat_timeout)
    assert not any(HEARTBEAT_ERROR in _emcy_codes(tap, n) for n in rig.config.node_ids)


def test_master_heartbeat_can_be_switched_off(make_config, robot, tap_on):
    config = replace(make_config(), master=MasterConfig(heartbeat=False))
    tap = tap_on(config.bus.channel)
    with SimulatedCobot(config, FirstOrderPlant(robot.q_home)) as sim, Cobot(config, robot) as cobot:
        cobot.enable()
        time.sleep(2 * config.timing.heartbeat_timeout)
        assert tap.with_id(0x700 + MASTER) == []
        assert all(slave.value((CONSUMER_HEARTBEAT_TIME, 1)) == 0 for slave in sim.drives)
        assert all(d.state == OPERATION_ENABLED for d in sim.drives)


def test_consumer_starts_with_the_first_heartbeat_and_reports_a_loss_once(make_config, tap_on, wait_until):
    """Device side alone, through a bare canopen master: SDO write of 0x1016, NMT start, heartbeats."""
    config = make_config()
    tap = tap_on(config.bus.channel)
    network = canopen.Network()
    with SimulatedCobot(config, FirstOrderPlant(np.zeros(6))) as sim:
        network.connect(interface="virtual", channel=config.bus.channel)
        try:
            node = network.add_node(3, str(eds_path(config.drives.eds)))
            node.sdo[CONSUMER_HEARTBEAT_TIME][1].raw = consumer_heartbeat_entry(MASTER, 100)
            node.nmt.send_command(0x01)  # NMT start
            drive = sim.drives[0]
            assert wait_until(lambda: drive.operational)
            time.sleep(0.3)  # three consumer times without any heartbeat: not started, no reaction
            assert drive.operational and HEARTBEAT_ERROR not in _emcy_codes(tap, 3)
            network.send_message(0x700 + MASTER, b"\x05")
            assert wait_until(lambda: not drive.operational, timeout=0.5)
            time.sleep(0.2)
            assert _emcy_codes(tap, 3).count(HEARTBEAT_ERROR) == 1
            assert [n for n in (4, 5, 6, 7, 8) if HEARTBEAT_ERROR in _emcy_codes(tap, n)] == []  # not configured
        finally:
            network.disconnect()
