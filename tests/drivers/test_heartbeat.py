"""Heartbeat consumer: loss detected within the consumer time, node named, streaming stops, quick stop."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from mrguide.drivers import DriverError, FeedbackLostError, HeartbeatLostError, load_cobot_bus_config
from mrguide.drivers.cia402 import OPERATION_ENABLED
from mrguide.drivers.heartbeat import HeartbeatConsumer

HB = 0.05  # heartbeat period of the test rigs (s)
REPO_TOML = Path(__file__).resolve().parents[2] / "configs" / "devices" / "cobot_bus.toml"


class _Network:
    """Minimal stand-in for canopen's Network: heartbeat frames of one node, delivered with their bus time."""

    def __init__(self, now):
        self.now = now
        self.callbacks = []

    def subscribe(self, can_id, callback):
        self.callbacks.append(callback)

    def heartbeat(self, state=5, at=None):
        self.callbacks[0](0x700, bytes([state]), self.now[0] if at is None else at)


def test_consumer_times_out_only_after_arming():
    now = [0.0]
    consumer = HeartbeatConsumer(timeout=0.1, clock=lambda: now[0])
    node = _Network(now)
    consumer.watch(node, 7)
    now[0] = 5.0
    assert consumer.expired() == []  # not armed: boot and configuration take their time
    consumer.arm()
    node.heartbeat()
    now[0] = 5.09
    assert consumer.expired() == []
    now[0] = 5.11
    assert consumer.expired() == [(7, pytest.approx(0.11))]
    node.heartbeat(5 | 0x80)  # the toggle bit is no part of the state
    assert consumer.expired() == [] and consumer.state(7) == 5


def test_a_heartbeat_that_waited_in_the_queue_counts_from_its_arrival_not_from_its_dispatch():
    """The receive thread fell behind (its process stalled): the bus clock (the receiver's horizon) advances only as
    the queued frames are dispatched, so the heartbeat that arrived during the stall is found before anything is
    judged lost; a real silence is still reported one consumer time after the last heartbeat's arrival."""
    horizon = [10.0]
    consumer = HeartbeatConsumer(timeout=0.1, clock=lambda: horizon[0])
    node = _Network(horizon)
    consumer.watch(node, 3)
    consumer.arm()
    node.heartbeat(at=10.0)
    horizon[0] = 10.08  # dispatched up to here when the stall began; the wall clock runs on to 10.3 meanwhile
    assert consumer.expired() == []
    node.heartbeat(at=10.09)  # arrived during the stall, dispatched after it
    horizon[0] = 10.15
    assert consumer.expired() == []
    horizon[0] = 10.2
    assert consumer.expired() == [(3, pytest.approx(0.11))]


@pytest.mark.parametrize("config", [None, REPO_TOML], ids=["defaults", "cobot_bus.toml"])
def test_real_timing_tolerates_three_lost_heartbeats_and_jitter_but_not_silence(config):
    """The margins of the real timing: the consumer time outlasts three heartbeats lost in a row, the next
    one half a period late (5 % frame loss tripped the former 2 x setting within seconds), and still
    notices a silent producer one consumer time after its last heartbeat."""
    timing = load_cobot_bus_config(config).timing
    period, now = timing.heartbeat_period, [0.0]
    consumer = HeartbeatConsumer(timing.heartbeat_timeout, clock=lambda: now[0])
    node = _Network(now)
    consumer.watch(node, 3)
    consumer.arm()
    node.heartbeat()
    for now[0] in np.arange(0.0, 4.5 * period, 0.001):  # heartbeats 1..3 lost, the 4th 0.5 period late
        assert consumer.expired() == [], f"tripped {now[0] * 1000:.0f} ms after the last heartbeat"
    node.heartbeat()
    now[0] += timing.heartbeat_timeout + 0.001  # then silence
    assert [n for n, _ in consumer.expired()] == [3]
    assert timing.heartbeat_timeout <= 0.2  # a dead PC or node is still noticed within 200 ms


def test_heartbeat_loss_stops_streaming_names_node_and_quick_stops(rig, tap_on):
    cobot, sim = rig.cobot, rig.sim
    tap = tap_on(rig.config.bus.channel)
    q, step = cobot.setpoint, np.full(6, 0.4 * cobot.period)  # 0.4 rad/s on every joint
    silenced_at = None
    with pytest.raises(HeartbeatLostError) as info:
        for k in range(2000):
            q = q + step
            cobot.stream(q)
            if k == 20:
                sim.faults.silence(5, heartbeat_only=True)  # PDOs still flow: only the heartbeat consumer can tell
                silenced_at = time.monotonic()
    error = info.value
    assert error.node_id == 5 and error.name == "elbow_joint"
    assert "node 5 (elbow_joint)" in str(error)
    status = cobot.status()
    assert status.fault is error and status.heartbeat_lost == (5,)
    assert status.fault_at - silenced_at <= rig.config.timing.heartbeat_timeout + HB
    with pytest.raises(HeartbeatLostError):
        cobot.stream(q)  # streaming stays stopped
    assert rig.wait_until(lambda: all(s != OPERATION_ENABLED for s in cobot.status().drive_states.values()))
    with pytest.raises(DriverError, match="no heartbeat"):
        cobot.reset_faults(timeout=0.1)  # the node is still silent: no reset
    sim.faults.unsilence(5)
    assert rig.wait_until(lambda: cobot.status().heartbeat_lost == ())
    cobot.reset_faults()
    cobot.enable()
    cobot.stream(cobot.setpoint)
    quick_stops = [m for m in tap.with_id(0x203) if m.timestamp > tap.frames[0].timestamp and m.data[:2] == b"\x02\x00"]
    assert quick_stops, "drive 3 never got the quick-stop controlword"


def test_silent_node_is_detected_by_feedback_and_heartbeat(make_rig):
    rig = make_rig(max_missed_feedback=5)
    rig.cobot.enable()
    silenced_at = time.monotonic()
    rig.sim.faults.silence(7)
    assert rig.wait_until(lambda: rig.cobot.status().fault is not None, timeout=3 * HB)
    fault = rig.cobot.status().fault
    assert isinstance(fault, FeedbackLostError) and fault.node_id == 7
    consumer_time = rig.config.timing.heartbeat_timeout
    assert rig.wait_until(lambda: rig.cobot.status().heartbeat_lost == (7,), timeout=consumer_time + HB)
    assert time.monotonic() - silenced_at <= consumer_time + HB + 0.01
    alive = [name for name in rig.cobot.joint_names if name != "wrist_2_joint"]
    assert rig.wait_until(lambda: all(rig.cobot.status().drive_states[n] != OPERATION_ENABLED for n in alive))
