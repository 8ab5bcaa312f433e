"""A control thread hung while holding the driver's lock must not hang the application with it.

`stop()` returns (its quick-stop request is applied when the thread comes back), and the calls that need
the lock raise a DriverError within a bounded time instead of waiting forever.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import replace

import pytest

from mrguide.drivers import Cobot, DriverError
from mrguide.drivers.cia402 import OPERATION_ENABLED
from mrguide.drivers.config import MasterConfig
from mrguide.drivers.mock import FirstOrderPlant, SimulatedCobot

#: Generous bound for a call to return or raise on a loaded 2-core machine (the lock wait itself is shorter).
BOUND = 3.0


def _call_with_deadline(call: Callable[[], object]) -> tuple[bool, BaseException | None, float]:
    """Run `call` in a helper thread (so a hang cannot hang the test): (finished, what it raised, seconds)."""
    outcome: dict[str, BaseException | None] = {"error": None}

    def run() -> None:
        try:
            call()
        except BaseException as exc:
            outcome["error"] = exc

    t0 = time.monotonic()
    thread = threading.Thread(target=run, daemon=True)
    thread.start()
    thread.join(BOUND)
    return not thread.is_alive(), outcome["error"], time.monotonic() - t0


@pytest.fixture
def cobot(make_config, robot) -> Iterator[Cobot]:
    """Enabled cobot whose devices do not consume the master's heartbeat, so they stay enabled while the
    control thread hangs and only the master's own quick stop can stop them."""
    config = replace(make_config(), master=MasterConfig(heartbeat=False))
    with SimulatedCobot(config, FirstOrderPlant(robot.q_home)), Cobot(config, robot) as cobot:
        cobot.enable()
        yield cobot


def test_stop_and_stream_return_while_the_control_thread_hangs_holding_the_lock(cobot, monkeypatch, wait_until):
    q = cobot.setpoint
    held, release = threading.Event(), threading.Event()
    cycle = cobot._loop.cycle

    def hang_holding_the_lock(tick) -> None:
        with cobot._core.lock:
            held.set()
            release.wait()
        cycle(tick)

    monkeypatch.setattr(cobot._loop, "cycle", hang_holding_the_lock)
    assert held.wait(1.0), "the control thread never took the lock"
    try:
        finished, error, _took = _call_with_deadline(cobot.stop)
        assert finished and error is None, f"stop() hung or raised: {error!r}"
        for name, call in (("stream", lambda: cobot.stream(q)), ("check", cobot.check)):
            finished, error, _took = _call_with_deadline(call)
            assert finished, f"{name}() still blocked after {BOUND} s"
            assert isinstance(error, DriverError) and "control thread" in str(error), f"{name}(): {error!r}"
    finally:
        release.set()
    # the thread is back: the quick stop requested while it hung is carried out
    assert wait_until(lambda: all(s != OPERATION_ENABLED for s in cobot.status().drive_states.values()))
    assert cobot.status().fault is None and not cobot.status().enabled


def test_a_control_cycle_that_stops_taking_setpoints_is_called_stalled_no_sooner_than_feedback_would_be(
    make_config, robot
):
    """The control thread stops (without the lock): `stream` fills the queue, then waits for room as long as the bus
    config tolerates missing feedback before it calls the cycle stalled (a shared PC's tolerance, not a robot's)."""
    config = replace(make_config(max_missed_feedback=100), master=MasterConfig(heartbeat=False))
    with SimulatedCobot(config, FirstOrderPlant(robot.q_home)), Cobot(config, robot) as cobot:
        cobot.enable()
        q, release = cobot.setpoint, threading.Event()
        cobot._loop.cycle = lambda tick: release.wait()  # the next cycle never returns
        try:
            time.sleep(0.05)  # the thread is in it
            for _ in range(cobot.setpoint_queue_depth):
                cobot.stream(q)
            finished, error, took = _call_with_deadline(lambda: cobot.stream(q))
        finally:
            release.set()
    wait = config.timing.control_period * (config.timing.setpoint_queue_depth + 100)
    assert finished and isinstance(error, DriverError) and "stalled" in str(error), error
    assert took >= wait  # never sooner than the feedback tolerance: a wall-clock lower bound, whatever the load
