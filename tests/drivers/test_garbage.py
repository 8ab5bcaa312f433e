"""Garbage and errors on the bus: ignored and counted, never a crash; bus errors reach the caller."""

from __future__ import annotations

import random

import can
import numpy as np
import pytest

from mrguide.config import ConfigError
from mrguide.drivers import BusError, BusOffError
from mrguide.drivers.bus import CAN_ERR_BUSOFF, open_bus
from mrguide.drivers.config import BusConfig


def _frame(can_id, data, **kw):
    return can.Message(arbitration_id=can_id, data=bytes(data), is_extended_id=kw.pop("extended", False), **kw)


def test_garbage_is_ignored_and_counted(rig, robot):
    cobot = rig.cobot
    rng = random.Random(1)
    unknown = [
        _frame(0x123, b"abc"),
        _frame(0x7FF, b""),
        _frame(0x1234567, b"x", extended=True),
        _frame(0x183, b"", is_remote_frame=True, dlc=6),
    ]
    unknown += [
        _frame(
            rng.choice([0x0FF, 0x1FF, 0x2FF, 0x7E5, 0x666, 0x100 + rng.randrange(0x80)]),
            rng.randbytes(rng.randrange(9)),
        )
        for _ in range(200)
    ]
    wrong_length = [
        _frame(0x183, b"\x27\x02"),
        _frame(0x283, b"\x01\x02\x03\x04\x05"),
        _frame(0x703, b""),
        _frame(0x704, b"\x05\x05"),
        _frame(0x085, b"\x10\x23\x01"),
        _frame(0x583, b"\x60\x00"),
        _frame(0x190, b"\x01"),
    ]
    wrong_length += [
        _frame(rng.choice([0x184, 0x185, 0x186]), rng.randbytes(rng.choice([0, 1, 2, 3, 4, 5, 7, 8])))
        for _ in range(200)
    ]
    before = cobot.stats()
    with can.Bus(interface="virtual", channel=rig.config.bus.channel) as intruder:
        for msg in unknown + wrong_length:
            intruder.send(msg)
    assert rig.wait_until(lambda: cobot.stats().bad_length_frames - before.bad_length_frames == len(wrong_length))
    after = cobot.stats()
    assert after.unknown_frames - before.unknown_frames == len(unknown)
    assert cobot.status().fault is None
    # the driver still works and its joint state is the plant's, not the garbage's
    q = cobot.setpoint
    for k in range(50):
        cobot.stream(q + 0.002 * k)
    assert rig.wait_until(lambda: np.allclose(cobot.joint_state().positions, rig.plant.joint_positions(), atol=0.01))
    assert set(cobot.joint_state().drive_states) == {"OPERATION ENABLED"}
    assert rig.sim.stats().receiver.handler_errors == 0


def test_bus_off_error_frame_reaches_the_caller(rig):
    with can.Bus(interface="virtual", channel=rig.config.bus.channel) as controller:
        controller.send(_frame(CAN_ERR_BUSOFF, b"\x00" * 8, is_error_frame=True))
    assert rig.wait_until(lambda: rig.cobot.status().fault is not None)
    with pytest.raises(BusOffError, match="bus-off"):
        rig.cobot.stream(rig.plant.joint_positions())
    assert rig.cobot.stats().error_frames == 1


def test_unopenable_bus_is_a_clear_error():
    with pytest.raises(BusError, match="socketcan channel 'mrguide-no-such-if'"):
        open_bus(BusConfig(interface="socketcan", channel="mrguide-no-such-if"))
    with pytest.raises(ConfigError, match="unknown python-can interface"):
        BusConfig(interface="socketcann")
