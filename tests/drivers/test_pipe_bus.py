"""python-can's `mrguide_pipe` interface: a CAN link between two processes, in order, lossless, no echo."""

from __future__ import annotations

import multiprocessing
import socket

import can
import pytest

from mrguide.drivers.mock.pipe_bus import pipe_link


def _bus(end) -> can.BusABC:
    return can.Bus(interface="mrguide_pipe", channel=str(end.fileno()))


def _echo_in_child(end) -> None:
    """The other process: answer every frame with its ID + 0x100 and the same data, until an ID 0x7FF frame."""
    bus = _bus(end)
    while (msg := bus.recv(10.0)) is not None and msg.arbitration_id != 0x7FF:
        bus.send(can.Message(arbitration_id=msg.arbitration_id + 0x100, data=msg.data, is_extended_id=False))
    bus.shutdown()


def test_frames_cross_to_another_process_in_order_and_none_comes_back_to_its_sender():
    master_end, device_end = pipe_link()
    child = multiprocessing.get_context("spawn").Process(target=_echo_in_child, args=(device_end,))
    child.start()
    device_end.close()
    bus = _bus(master_end)
    try:
        for i in range(200):
            bus.send(can.Message(arbitration_id=0x200 + i % 8, data=[i % 256, 1, 2], is_extended_id=False))
        answers = [bus.recv(10.0) for _ in range(200)]
        assert [(m.arbitration_id, m.data[0]) for m in answers] == [(0x300 + i % 8, i % 256) for i in range(200)]
        assert all(m.dlc == 3 and not m.is_extended_id for m in answers)
        assert bus.recv(0.05) is None  # its own frames never came back to it
        bus.send(can.Message(arbitration_id=0x7FF, data=[], is_extended_id=False))
        child.join(10.0)
        assert child.exitcode == 0
    finally:
        bus.shutdown()
        master_end.close()


def test_flags_and_remote_frames_are_carried():
    a, b = pipe_link()
    x, y = _bus(a), _bus(b)
    try:
        x.send(can.Message(arbitration_id=0x1ABCDEF, data=[9], is_extended_id=True))
        x.send(can.Message(arbitration_id=0x601, is_remote_frame=True, dlc=8, is_extended_id=False))
        ext, rtr = y.recv(1.0), y.recv(1.0)
        assert ext.is_extended_id and ext.arbitration_id == 0x1ABCDEF and bytes(ext.data) == b"\x09"
        assert rtr.is_remote_frame and rtr.dlc == 8 and len(rtr.data) == 0
    finally:
        x.shutdown()
        y.shutdown()


def test_a_closed_far_end_is_a_receive_error_and_a_bad_channel_is_refused():
    a, b = pipe_link()
    x = _bus(a)
    b.close()
    with pytest.raises(can.CanOperationError, match="other end closed"):
        x.recv(1.0)
    with pytest.raises(can.CanOperationError, match="classic CAN"):
        x.send(can.Message(arbitration_id=0x100, data=bytes(12), is_fd=True, is_extended_id=False))
    x.shutdown()
    a.close()
    with pytest.raises(can.CanInitializationError, match="file descriptor"):
        can.Bus(interface="mrguide_pipe", channel="not-a-number")
    with open(__file__, "rb") as f, pytest.raises(can.CanInitializationError, match="file descriptor"):
        can.Bus(interface="mrguide_pipe", channel=str(f.fileno()))
    with socket.socket() as tcp, pytest.raises(can.CanInitializationError, match="not an end of a pipe_link"):
        can.Bus(interface="mrguide_pipe", channel=str(tcp.fileno()))
