"""Real-time hygiene for the control and receive threads: SCHED_FIFO when permitted, a settled heap."""

from __future__ import annotations

import gc
import logging
import os

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


def freeze_heap() -> None:
    """Collect garbage now and exempt every object alive from later collections (call before the bus starts).

    A full collection scans everything the process has loaded (torch, pinocchio, EDS dictionaries) with the
    GIL held, and runs the finalizers of whatever garbage it finds, in the thread that triggered it, which
    may be the control thread: tens of ms measured here, against a 4 ms cycle and a 100 ms heartbeat.
    """
    gc.collect()
    gc.freeze()
