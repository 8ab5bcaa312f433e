"""Real-time hygiene while the bus runs: a frozen heap and short GIL slices, both undone after the outermost block."""

from __future__ import annotations

import gc
import sys

from mrguide.drivers.realtime import GIL_SWITCH_INTERVAL_S, realtime_hygiene


def test_short_gil_slices_and_a_frozen_heap_while_the_block_runs_then_the_process_as_before():
    before = sys.getswitchinterval()
    sys.setswitchinterval(0.004)
    try:
        with realtime_hygiene():
            assert sys.getswitchinterval() == GIL_SWITCH_INTERVAL_S < 0.004
            assert gc.get_freeze_count() > 0
            with realtime_hygiene():  # nested: nothing set or undone inside
                assert sys.getswitchinterval() == GIL_SWITCH_INTERVAL_S
            assert sys.getswitchinterval() == GIL_SWITCH_INTERVAL_S and gc.get_freeze_count() > 0
        assert sys.getswitchinterval() == 0.004 and gc.get_freeze_count() == 0
    finally:
        sys.setswitchinterval(before)
