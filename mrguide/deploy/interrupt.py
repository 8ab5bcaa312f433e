"""Ctrl-C in a production run: the first press finishes the cycle in progress, the second stops at once."""

from __future__ import annotations

import contextlib
import signal
import sys
import threading
from collections.abc import Iterator


class CycleInterrupt:
    """Whether the operator asked the run to stop after the current cycle (`requested`)."""

    def __init__(self) -> None:
        self.requested = False

    def _on_sigint(self, signum: int, frame: object) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        print("\nCtrl-C: finishing the current cycle, then stopping (Ctrl-C again: quick stop now)", file=sys.stderr)


@contextlib.contextmanager
def finish_cycle_on_interrupt() -> Iterator[CycleInterrupt]:
    """While inside: the first SIGINT sets `requested`, the second raises KeyboardInterrupt (the runtime quick-stops).
    Outside the main thread (where no signal handler can be set) Ctrl-C keeps its usual meaning."""
    interrupt = CycleInterrupt()
    if threading.current_thread() is not threading.main_thread():
        yield interrupt
        return
    previous = signal.signal(signal.SIGINT, interrupt._on_sigint)
    try:
        yield interrupt
    finally:
        signal.signal(signal.SIGINT, previous)
