"""Traffic monitor: every CANopen service decoded into a readable line."""

from __future__ import annotations

import struct
import threading

import can
import pytest

from mrguide.drivers import CobotBusConfig
from mrguide.drivers.monitor import FrameDecoder, monitor


@pytest.fixture(scope="module")
def decoder(robot):
    return FrameDecoder(CobotBusConfig(), robot.joint_names)


@pytest.mark.parametrize(
    "can_id, data, kind, words",
    [
        (0x000, b"\x01\x05", "nmt", ["NMT OPERATIONAL", "node 5"]),
        (0x000, b"\x82\x00", "nmt", ["RESET COMMUNICATION", "all nodes"]),
        (0x080, b"", "sync", ["SYNC"]),
        (0x705, b"\x05", "heartbeat", ["node 5 (elbow_joint)", "OPERATIONAL"]),
        (0x703, b"\x00", "heartbeat", ["BOOT-UP"]),
        (0x77F, b"\x05", "heartbeat", ["node 127 (master)", "OPERATIONAL"]),
        (0x083, struct.pack("<HB5s", 0x8130, 0x11, b""), "emcy", ["node 3 (shoulder_pan_joint)", "0x8130"]),
        (0x084, struct.pack("<HB5s", 0x2310, 0x03, b""), "emcy", ["node 4 (shoulder_lift_joint)", "0x2310", "Current"]),
        (0x203, struct.pack("<Hi", 0x0F, 0), "pdo", ["RPDO1", "controlword=0x000F", "target=0 (+0.0000 rad)"]),
        (0x183, struct.pack("<Hi", 0x1237, 131072 * 101 // 4), "pdo", ["TPDO1", "OPERATION ENABLED", "+1.5708 rad"]),
        (0x283, struct.pack("<i", -1000), "pdo", ["TPDO2", "velocity=-1000"]),
        (
            0x190,
            struct.pack("<HHH", 523, 1, 0),
            "pdo",
            ["node 16 (vacuum)", "level=52.3 kPa", "gripped=yes", "lost=no"],
        ),
        (0x210, struct.pack("<I", 1 << 24), "pdo", ["vacuum=on", "blow_off=off"]),
        (0x183, b"\x01", "pdo", ["bad length 1, expected 6"]),
        (
            0x605,
            bytes([0x2F, 0x60, 0x60, 0x00, 0x08, 0, 0, 0]),
            "sdo",
            ["request to node 5", "download 0x6060:00", "value=8"],
        ),
        (0x605, bytes([0x2F, 0xC2, 0x60, 0x02, 0xFD, 0, 0, 0]), "sdo", ["0x60C2:02", "value=-3"]),
        (0x585, bytes([0x80, 0x60, 0x60, 0x00, 0x30, 0x00, 0x09, 0x06]), "sdo", ["abort", "code=0x06090030"]),
        (0x123, b"\xaa", "unknown", ["0x123", "not part"]),
    ],
)
def test_decoder_lines(decoder, can_id, data, kind, words):
    got_kind, text = decoder.decode(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
    assert got_kind == kind
    for word in words:
        assert word in text, text


def test_monitor_prints_live_traffic(make_config, robot):
    config = make_config()
    lines = []

    def sender():
        with can.Bus(interface="virtual", channel=config.bus.channel) as bus:
            for _ in range(5):
                bus.send(can.Message(arbitration_id=0x080, data=b"", is_extended_id=False))
            bus.send(can.Message(arbitration_id=0x706, data=b"\x7f", is_extended_id=False))

    thread = threading.Thread(target=sender)
    counts = monitor(config, robot.joint_names, 0.3, lines.append, listening=thread.start)
    thread.join()
    assert counts == {"sync": 5, "heartbeat": 1}
    assert lines[-1].endswith("HEARTBEAT node 6 (wrist_1_joint): PRE-OPERATIONAL")
