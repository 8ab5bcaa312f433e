"""How far a simulated cell's world runs behind the wall clock (drivers/mock/sync_backlog.py)."""

from __future__ import annotations

import pytest

from mrguide.drivers.mock.sync_backlog import SyncBacklog

PERIOD = 0.004


def test_syncs_handled_on_time_leave_no_backlog_and_a_stall_leaves_its_length():
    backlog = SyncBacklog(PERIOD)
    assert backlog.take() == 0.0  # no SYNC yet
    for k in range(100):
        backlog.tick(10.0 + k * PERIOD + (0.001 if k % 7 == 0 else 0.0))  # on time, with a millisecond of jitter
    assert backlog.take() == pytest.approx(0.001)
    # the handling thread waits 0.3 s for a CPU, then works off the 75 SYNCs queued meanwhile in a burst
    t = 10.0 + 100 * PERIOD + 0.3
    for k in range(100, 200):
        backlog.tick(max(t, 10.0 + k * PERIOD))
        t += 0.0001
    assert backlog.take() == pytest.approx(0.3, abs=0.01)
    backlog.tick(10.0 + 200 * PERIOD)  # caught up: the next interval starts afresh
    assert backlog.take() == 0.0
