"""Real-time hygiene for the control and receive threads: SCHED_FIFO when permitted, a settled heap while the bus runs."""

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


_frozen = 0  # nesting depth of settled_heap blocks
_frozen_lock = threading.Lock()


@contextlib.contextmanager
def settled_heap() -> Iterator[None]:
    """Collect garbage now and exempt every object alive from collections while the block runs (enter it before the
    bus starts); afterwards they are collectable again, and what the block left behind is collected and finalized
    here, in the thread that leaves it.

    A full collection scans everything the process has loaded (torch, pinocchio, EDS dictionaries) with the GIL held,
    and runs the finalizers of whatever garbage it finds, in the thread that triggered it, which may be the control
    thread: tens of ms measured here, against a 4 ms cycle and a 100 ms heartbeat. Frozen for good, though, the heap
    also keeps every cycle that a frozen object came to reference (a finished run's runtime and its Ruckig objects,
    reported as leaks when the interpreter exits), so the freeze ends with the block. Blocks nest: the outermost
    freezes and thaws.
    """
    global _frozen
    with _frozen_lock:
        _frozen += 1
        if _frozen == 1:
            gc.collect()
            gc.freeze()
    try:
        yield
    finally:
        with _frozen_lock:
            _frozen -= 1
            if _frozen == 0:
                gc.unfreeze()
                gc.collect()


_switch_users: list[float] = []  # the switch interval each holder asked for, in order
_switch_default: float | None = None  # the interpreter's before the first holder
_switch_lock = threading.Lock()


def hold_switch_interval(seconds: float) -> None:
    """Set Python's thread switch interval to `seconds` (the shortest any holder asked for) until the matching
    `release_switch_interval`: a thread waiting for the GIL waits at most about that long for a thread running Python
    code to let go of it (the interpreter's default, 5 ms, is longer than a control period)."""
    global _switch_default
    with _switch_lock:
        if not _switch_users:
            _switch_default = sys.getswitchinterval()
        _switch_users.append(seconds)
        sys.setswitchinterval(min(_switch_users))


def release_switch_interval(seconds: float) -> None:
    """End one `hold_switch_interval(seconds)`; the last one restores the interpreter's interval."""
    with _switch_lock:
        if seconds not in _switch_users:
            return
        _switch_users.remove(seconds)
        if _switch_users:
            sys.setswitchinterval(min(_switch_users))
        elif _switch_default is not None:
            sys.setswitchinterval(_switch_default)
