"""`Cobot.disconnect()` always completes: every node gets NMT pre-operational and the bus is closed,
whatever raised on the way (a heartbeat with an undefined NMT state, a failing send)."""

from __future__ import annotations

import time

import can
import pytest

from mrguide.drivers import DriverError

NMT_PRE_OPERATIONAL = 0x80


def _pre_operational_commands(tap) -> set[int]:
    """Node IDs the master sent NMT enter pre-operational to."""
    return {m.data[1] for m in tap.with_id(0x000) if len(m.data) == 2 and m.data[0] == NMT_PRE_OPERATIONAL}


def _assert_torn_down(rig, bus: can.BusABC, tap) -> None:
    time.sleep(0.05)  # the last frames reach the tap
    assert _pre_operational_commands(tap) == set(rig.config.node_ids)
    assert not rig.cobot.status().connected
    assert bus._is_shutdown  # python-can's flag: the master's bus was closed


def test_disconnect_after_a_heartbeat_with_an_undefined_nmt_state(make_rig, tap_on, wait_until):
    rig = make_rig()
    rig.cobot.enable()
    tap = tap_on(rig.config.bus.channel)
    bus = rig.cobot._core.network.bus
    rig.sim.faults.silence(5, heartbeat_only=True)  # no real heartbeat overwrites the undefined state below
    sender = can.Bus(interface="virtual", channel=rig.config.bus.channel)
    try:
        sender.send(can.Message(arbitration_id=0x705, data=[0x42], is_extended_id=False))
        assert wait_until(lambda: "UNKNOWN" in rig.cobot.status().nmt_states[5])
    finally:
        sender.shutdown()
    rig.cobot.disconnect()  # used to raise KeyError from canopen's NMT state lookup
    _assert_torn_down(rig, bus, tap)


def test_every_node_gets_its_nmt_command_and_the_bus_closes_when_steps_fail(make_rig, tap_on, monkeypatch):
    rig = make_rig()
    tap = tap_on(rig.config.bus.channel)
    network = rig.cobot._core.network
    bus = network.bus
    send = network.send_message

    def first_nmt_fails(can_id, data, remote=False):
        if can_id == 0 and data[1] == rig.config.node_ids[0] and not failed:
            failed.append(can_id)
            raise can.CanError("transmit buffer full")
        send(can_id, data, remote)

    receiver = rig.cobot._core.receiver
    stop_receiver = receiver.stop

    def stop_then_raise():
        stop_receiver()
        raise RuntimeError("receive thread did not confirm")

    failed: list[int] = []
    monkeypatch.setattr(network, "send_message", first_nmt_fails)
    monkeypatch.setattr(receiver, "stop", stop_then_raise)
    rig.cobot.disconnect()
    assert failed
    time.sleep(0.05)
    assert _pre_operational_commands(tap) == set(rig.config.node_ids[1:])  # the first one was lost on the bus
    assert not rig.cobot.status().connected and bus._is_shutdown
    with pytest.raises(DriverError, match="not connected"):
        rig.cobot.joint_state()
