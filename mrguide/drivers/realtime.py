"""Real-time hygiene for the control and receive threads: SCHED_FIFO when permitted; a settled heap and short GIL
slices while the bus runs."""

from __future__ import annotations

import contextlib
import gc
import logging
import os
import sys
import threading
from collections.abc import Iterator

logger = logging.getLogger(__name__)


def make_current_thread_realtime(priority: int) -> bool:
    """Give the calling thread SCHED_FIFO `priority` (1..99); threads it starts inherit it.

    Returns False and logs a warning when the OS or the permissions do not allow it; the thread then keeps
    normal scheduling (and its timing suffers under CPU load).
    """
    if not 1 <= priority <= 99:
        raise ValueError(f"SCHED_FIFO priority must be 1..99, got {priority}")
    if not hasattr(os, "sched_setscheduler"):
        logger.warning("real-time priority requested but this OS has no sched_setscheduler")
        return False
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except OSError as exc:
        logger.warning("cannot get SCHED_FIFO priority %d (%s): keeping normal scheduling", priority, exc)
        return False
    return True


#: s: how long a thread may keep the GIL while another waits for it (Python's default, 5 ms, is longer than the 4 ms
#: control period: a control thread that woke while another thread ran Python code lost its cycle). Measured with
#: benchmarks/deploy.py beside two trainings, 7 alternating pairs of 8-episode runs: 35 missed cycles at 5 ms, 6 at
#: 1 ms (docs/performance.md).
GIL_SWITCH_INTERVAL_S = 0.001

_depth = 0  # nesting depth of realtime_hygiene blocks
_lock = threading.Lock()
_saved_interval = 0.005  # the switch interval before the outermost block


@contextlib.contextmanager
def realtime_hygiene() -> Iterator[None]:
    """Enter before the bus starts: a settled heap and short GIL slices while the block runs, both undone after it.

    Settled heap: garbage is collected now and every object alive is exempt from collections until the block ends;
    then what the block left behind is collected and finalized here, in the thread that leaves it. A full collection
    scans everything the process has loaded (torch, pinocchio, EDS dictionaries) with the GIL held, and runs the
    finalizers of whatever garbage it finds, in the thread that triggered it, which may be the control thread: tens
    of ms measured here, against a 4 ms cycle and a 100 ms heartbeat. Frozen for good, though, the heap also keeps
    every cycle that a frozen object came to reference (a finished run's runtime and its Ruckig objects, reported as
    leaks when the interpreter exits), so the freeze ends with the block.

    Short GIL slices: `sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)`, the process's setting restored after the block.

    Blocks nest: the outermost one sets and restores.
    """
    global _depth, _saved_interval
    with _lock:
        _depth += 1
        if _depth == 1:
            gc.collect()
            gc.freeze()
            _saved_interval = sys.getswitchinterval()
            sys.setswitchinterval(GIL_SWITCH_INTERVAL_S)
    try:
        yield
    finally:
        with _lock:
            _depth -= 1
            if _depth == 0:
                sys.setswitchinterval(_saved_interval)
                gc.unfreeze()
                gc.collect()
