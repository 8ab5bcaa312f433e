"""A bus shut down while one of its periodic tasks is in the middle of a send (a heartbeat producer at the end of a
run) lets that send finish first: no task raises in its thread on a closed link, nothing reaches stderr."""

from __future__ import annotations

import threading
import time

import can
import pytest

from mrguide.drivers.mock.faults import FaultInjector, FaultyBus
from mrguide.drivers.mock.pipe_bus import PipeBus, pipe_link


class _SlowSend:
    """Wraps a bus's `send` so that each send takes `seconds` (the task is caught mid-send by a shutdown)."""

    def __init__(self, bus: can.BusABC, seconds: float) -> None:
        self.inner, self.seconds, self.started = bus.send, seconds, threading.Event()

    def __call__(self, msg: can.Message, timeout: float | None = None) -> None:
        self.started.set()
        time.sleep(self.seconds)
        self.inner(msg, timeout)


@pytest.fixture
def thread_errors(monkeypatch):
    errors: list[BaseException] = []
    monkeypatch.setattr(threading, "excepthook", lambda args: errors.append(args.exc_value))
    return errors


def _heartbeat() -> can.Message:
    return can.Message(arbitration_id=0x703, data=[5], is_extended_id=False)


def test_a_pipe_bus_waits_for_a_task_mid_send_before_closing_its_socket(thread_errors):
    near, far = pipe_link()
    bus = PipeBus(channel=near.fileno())
    slow = _SlowSend(bus, 0.05)
    bus.send = slow  # type: ignore[method-assign]
    bus.send_periodic(_heartbeat(), 0.01)
    assert slow.started.wait(5.0)
    bus.shutdown()
    time.sleep(0.3)  # a task still in its send would now find the socket closed and raise in its thread
    assert thread_errors == []
    near.close()
    far.close()


def test_a_faulty_bus_waits_for_a_task_mid_send_before_shutting_down_the_bus_it_wraps(thread_errors):
    inner = can.Bus(interface="virtual", channel="periodic-shutdown")
    bus = FaultyBus(inner, FaultInjector())
    slow = _SlowSend(inner, 0.05)
    inner.send = slow  # type: ignore[method-assign]
    bus.send_periodic(_heartbeat(), 0.01)
    assert slow.started.wait(5.0)
    bus.shutdown()
    time.sleep(0.3)
    assert thread_errors == []
