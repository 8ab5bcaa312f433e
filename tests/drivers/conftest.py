"""Fixtures for the driver tests: a simulated cobot and a connected master on a private virtual channel.

Every rig uses its own virtual channel, so tests never hear each other. Timing is shortened (50 ms
heartbeats) and the feedback watchdog is lenient, so a busy CI machine does not trip it by accident;
tests that exercise a watchdog set their own values.
"""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace

import can
import pytest

from mrguide.drivers import Cobot, CobotBusConfig
from mrguide.drivers.config import BusConfig, TimingConfig
from mrguide.drivers.mock import FirstOrderParams, FirstOrderPlant, SimulatedCobot
from mrguide.drivers.realtime import settled_heap
from mrguide.robot import RobotSpec, load_robot

TEST_TIMING = TimingConfig(
    heartbeat_period=0.05, boot_timeout=2.0, enable_timeout=1.0, max_missed_feedback=50, setpoint_queue_depth=8
)


def _make_config(**timing: float | int) -> CobotBusConfig:
    """Default bus description on a fresh virtual channel, with test timing (overridable per key)."""
    return replace(
        CobotBusConfig(), bus=BusConfig(channel=f"test-{uuid.uuid4().hex[:10]}"), timing=replace(TEST_TIMING, **timing)
    )


@pytest.fixture
def make_config() -> Callable[..., CobotBusConfig]:
    return _make_config


@pytest.fixture(scope="session")
def robot() -> RobotSpec:
    return load_robot()


@dataclass
class Rig:
    config: CobotBusConfig
    plant: FirstOrderPlant
    sim: SimulatedCobot
    cobot: Cobot

    def wait_until(self, predicate: Callable[[], bool], timeout: float = 10.0) -> bool:
        return _wait_until(predicate, timeout)


def _wait_until(predicate: Callable[[], bool], timeout: float = 10.0) -> bool:
    """Poll `predicate` every 2 ms; False if it is still false after `timeout` seconds (generous: what a test waits
    for happens in milliseconds on an idle machine, and the bound only matters when it never happens)."""
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            return False
        time.sleep(0.002)
    return True


@pytest.fixture
def wait_until() -> Callable[..., bool]:
    return _wait_until


@pytest.fixture
def make_rig(robot: RobotSpec) -> Iterator[Callable[..., Rig]]:
    """Factory: `make_rig(plant_params=None, **timing)` -> connected Rig; everything is torn down after."""
    started: list[Rig] = []

    def factory(plant_params: FirstOrderParams | None = None, **timing: float | int) -> Rig:
        config = _make_config(**timing)
        plant = FirstOrderPlant(robot.q_home, plant_params)
        sim = SimulatedCobot(config, plant)
        sim.start()
        cobot = Cobot(config, robot)
        rig = Rig(config, plant, sim, cobot)
        started.append(rig)
        cobot.connect()
        return rig

    with settled_heap():  # as the deploy does: no collection (and no finalizer of an old rig) in the bus threads
        yield factory
        for rig in started:
            rig.cobot.disconnect()
            rig.sim.stop()
        started.clear()
    # leaving the block collected this rig's garbage here, not in the next rig's threads


@pytest.fixture
def rig(make_rig: Callable[..., Rig]) -> Rig:
    """Connected and enabled cobot with its simulated devices."""
    rig = make_rig()
    rig.cobot.enable()
    return rig


@dataclass
class BusTap:
    """A passive listener on a virtual channel that keeps every frame it hears."""

    channel: str
    frames: list[can.Message] = field(default_factory=list)

    def __post_init__(self) -> None:
        self._bus = can.Bus(interface="virtual", channel=self.channel)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            msg = self._bus.recv(0.05)
            if msg is not None:
                self.frames.append(msg)

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self._bus.shutdown()

    def with_id(self, can_id: int) -> list[can.Message]:
        return [m for m in list(self.frames) if m.arbitration_id == can_id and not m.is_error_frame]


@pytest.fixture
def tap_on() -> Iterator[Callable[[str], BusTap]]:
    taps: list[BusTap] = []

    def factory(channel: str) -> BusTap:
        taps.append(BusTap(channel))
        return taps[-1]

    yield factory
    for tap in taps:
        tap.close()
