"""Stalls: heartbeats are judged on the bus clock, as a device's CAN controller stamps a frame on its arrival.

A receive thread that falls behind its queue (descheduled, or blocked by another thread) finds the heartbeats that
arrived meanwhile before anything is judged lost, on the master and on the simulated devices alike. The simulated
devices run in the master's process, so a stall of the whole process (the OS, the garbage collector, a thread
holding the GIL) stops them too: on the bus, the gap in the master's heartbeat is the stall. A stall shorter than
the consumer time less one producer period leaves every drive enabled; a longer one disables them by their own
heartbeat consumer, as on a robot.
"""

from __future__ import annotations

import sys
import time

from mrguide.drivers.cia402 import OPERATION_ENABLED
from mrguide.drivers.mock.drive_sim import SWITCH_ON_DISABLED

from .conftest import TEST_TIMING


def _hold_the_interpreter(seconds: float) -> None:
    """Keep every other Python thread of this process from running for `seconds` (the GIL is never offered)."""
    previous = sys.getswitchinterval()
    sys.setswitchinterval(100.0)
    try:
        end = time.perf_counter() + seconds
        while time.perf_counter() < end:
            pass
    finally:
        sys.setswitchinterval(previous)


def _enabled(rig) -> bool:
    return rig.cobot.status().fault is None and all(d.state == OPERATION_ENABLED for d in rig.sim.drives)


def test_stalls_shorter_than_the_consumer_time_leave_every_drive_enabled(rig, wait_until):
    stall = TEST_TIMING.heartbeat_timeout - TEST_TIMING.heartbeat_period - 0.05  # 125 ms against 225 ms
    for _ in range(3):
        _hold_the_interpreter(stall)
        time.sleep(0.3)  # the devices answer and the master supervises on the resumed bus
        assert _enabled(rig), rig.cobot.status()


def test_the_control_threads_misses_during_a_stall_are_time_off_a_cpu(rig):
    """Another thread holding the GIL skips the control thread's deadlines; the gap that skipped them is counted as
    time the control thread spent not computing (blocked on the GIL, or queued for a CPU on a busy machine)."""
    before = rig.cobot.stats().misses
    _hold_the_interpreter(0.125)
    time.sleep(0.05)
    misses = rig.cobot.stats().misses
    assert misses.gaps > before.gaps
    assert misses.wall_s - before.wall_s >= 0.1
    assert misses.cpu_s - before.cpu_s < 0.05
    assert misses.runq_s is not None and misses.off_cpu_s is not None
    waited = (misses.runq_s - (before.runq_s or 0.0)) + (misses.off_cpu_s - (before.off_cpu_s or 0.0))
    assert waited >= 0.09


def test_a_stall_longer_than_the_consumer_time_disables_the_drives_by_their_own_heartbeat_consumer(rig, wait_until):
    _hold_the_interpreter(2 * TEST_TIMING.heartbeat_timeout)
    assert wait_until(lambda: all(d.state == SWITCH_ON_DISABLED and not d.operational for d in rig.sim.drives))
    assert wait_until(lambda: rig.cobot.status().fault is not None)  # and the master stops streaming


class _Blocker:
    """A receive callback that blocks its receive thread once, for `seconds`, when armed (GIL released: every other
    thread runs on). Frames that arrive meanwhile wait in that receiver's queue."""

    def __init__(self) -> None:
        self.seconds = 0.0

    def __call__(self, can_id: int, data: bytes, timestamp: float) -> None:
        seconds, self.seconds = self.seconds, 0.0
        time.sleep(seconds)


def test_a_master_receiver_behind_its_queue_does_not_count_the_waiting_heartbeats_as_lost(rig):
    """The master's receive thread stops for twice the consumer time while its control thread and the devices run
    on: the devices' heartbeats wait in its queue. Judged on their arrival, no node is lost (judged on when the thread
    got to them, the control thread would report every node's heartbeat lost)."""
    blocker = _Blocker()
    rig.cobot._core.network.subscribe(0x183, blocker)  # node 3's status TPDO, every SYNC
    for _ in range(3):
        blocker.seconds = 2 * TEST_TIMING.heartbeat_timeout
        time.sleep(blocker.seconds + 0.3)
        assert _enabled(rig), rig.cobot.status()


def test_a_device_receiver_behind_its_queue_does_not_count_the_waiting_heartbeats_as_lost(make_rig):
    """The simulator's receive thread stops for twice the consumer time while its device clock and the master run
    on: the master's heartbeats wait in its queue. Judged on their arrival, the drives stay enabled. (The devices do
    not answer SYNC meanwhile, as a stalled device would not: the master's feedback check is set to tolerate it.)

    The consumer time is twice the other tests' (450 ms): the simulated devices send their own heartbeats every
    150 ms, and at 225 ms a busy machine's 76 ms late wake-up of a device's heartbeat sender, which this test does
    not stall, failed it about one run in four."""
    rig = make_rig(max_missed_feedback=1000, heartbeat_timeout_factor=2 * TEST_TIMING.heartbeat_timeout_factor)
    timeout = rig.config.timing.heartbeat_timeout
    rig.cobot.enable()
    blocker = _Blocker()
    rig.sim._network.subscribe(0x203, blocker)  # node 3's RPDO from the master, every SYNC
    for _ in range(3):
        blocker.seconds = 2 * timeout
        time.sleep(blocker.seconds + 0.3)
        assert _enabled(rig), rig.cobot.status()
