"""A setpoint queue that runs dry while the arm moves: counted by the control thread, logged by the next `stream`
(the control thread does no I/O: a write to stderr lets go of the GIL mid-cycle)."""

from __future__ import annotations

import logging

import numpy as np
import pytest


def test_an_underrun_is_counted_and_logged_by_the_next_stream(rig, caplog: pytest.LogCaptureFixture) -> None:
    cobot = rig.cobot
    samples = []
    cobot.add_cycle_observer(samples.append)
    q = cobot.setpoint
    step = np.full(6, 0.2 * cobot.period)  # 0.2 rad/s on every joint: moving
    for _ in range(20):
        q = q + step
        cobot.stream(q)
    # all 20 taken from the queue, then a cycle that found it empty: the last dry spell, after every `stream` call
    # (however busy the machine is, an earlier one between two calls was logged by the later call)
    assert rig.wait_until(lambda: sum(s.setpoint is not None for s in samples) == 20 and samples[-1].setpoint is None)
    assert cobot.stats().underruns >= 1
    caplog.clear()
    with caplog.at_level(logging.WARNING, logger="mrguide.drivers"):
        cobot.stream(q)  # the held setpoint again: a step of 0
    dry = [r for r in caplog.records if "ran dry" in r.getMessage()]
    assert len(dry) == 1 and dry[0].threadName == "MainThread"
    assert f"({cobot.stats().underruns} so far)" in dry[0].getMessage()
