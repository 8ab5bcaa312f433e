"""Cycle timer: absolute deadlines (no drift), skipped deadlines counted; lateness statistics."""

from __future__ import annotations

import time

import pytest

from mrguide.drivers.cycle import CycleStats, CycleTimer


class FakeClock:
    def __init__(self, overshoot: float) -> None:
        self.t = 100.0
        self.overshoot = overshoot

    def __call__(self) -> float:
        return self.t

    def sleep(self, dt: float) -> None:
        self.t += dt + self.overshoot


def test_deadlines_do_not_drift_with_sleep_overshoot():
    clock = FakeClock(overshoot=0.0007)
    timer = CycleTimer(0.004, clock=clock, sleep=clock.sleep)
    timer.start()
    ticks = [timer.wait() for _ in range(1000)]
    assert ticks[-1].deadline == pytest.approx(100.0 + 1000 * 0.004)
    assert clock.t - ticks[-1].deadline == pytest.approx(0.0007)  # overshoot stays one overshoot
    assert all(t.skipped == 0 for t in ticks)


def test_late_cycle_skips_missed_deadlines():
    clock = FakeClock(overshoot=0.0)
    timer = CycleTimer(0.004, clock=clock, sleep=clock.sleep)
    timer.start()
    timer.wait()
    clock.t += 0.0145  # the cycle body stalled for 3.6 periods
    tick = timer.wait()
    assert tick.skipped == 2
    assert tick.index == 4
    assert tick.deadline == pytest.approx(100.0 + 4 * 0.004)


def test_a_wake_up_more_than_a_period_late_skips_in_its_own_cycle():
    """The sleep that overshot holds the gap's time, so the cycle that wakes from it is the one that skips."""
    clock = FakeClock(overshoot=0.0)
    timer = CycleTimer(0.004, clock=clock, sleep=clock.sleep)
    timer.start()
    clock.overshoot = 0.009  # woken 2.25 periods late
    tick = timer.wait()
    assert (tick.index, tick.skipped, tick.slept) == (3, 2, pytest.approx(0.004))
    clock.overshoot = 0.0
    assert timer.wait().skipped == 0


def test_real_clock_keeps_the_average_rate():
    timer = CycleTimer(0.002)
    timer.start()
    start = time.monotonic()
    for _ in range(100):
        tick = timer.wait()
    assert tick.index >= 100
    assert time.monotonic() - start == pytest.approx(tick.index * 0.002, abs=0.015)


def test_cycle_stats_percentiles_and_missed():
    stats = CycleStats(capacity=8)
    for i in range(10):
        stats.record(i * 1e-4, skipped=1 if i == 3 else 0)
    summary = stats.summary()
    assert summary.cycles == 10 and summary.missed == 1
    assert summary.lateness_max == pytest.approx(9e-4)  # ring buffer keeps the last 8


def test_cycle_stats_work_time():
    stats = CycleStats(capacity=8, period=4e-3)
    assert stats.summary().work_max == 0.0
    for i in range(10):
        stats.record(0.0, skipped=0)
        stats.record_work((i + 1) * 1e-3)
    summary = stats.summary()
    assert summary.work_max == pytest.approx(10e-3)
    assert 9e-3 < summary.work_p99 < 10e-3  # the last 8 cycles: 3..10 ms
    assert summary.overruns == 6  # 5..10 ms took longer than the 4 ms period (counted over all, not the ring)
