"""What the process and its host spent, for the production logs: memory, and the CPU time a hypervisor took.

Linux only (/proc); elsewhere the readings are None. A virtual machine's "steal" time is time its virtual CPUs were
ready to run and the host ran something else: no priority inside the guest gets it back, so a control cycle missed
while the host stole is told apart from one the process missed itself.
"""

from __future__ import annotations

import gc
import os
import resource
import time
from pathlib import Path


def peak_rss_mb() -> float:
    """The process's peak resident set so far (MB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: KiB


def resident_mb() -> float | None:
    """The process's resident set now (MB), from /proc/self/statm; None where there is no /proc (not Linux)."""
    try:
        pages = int(Path("/proc/self/statm").read_text().split()[1])
    except (OSError, IndexError, ValueError):
        return None
    return pages * resource.getpagesize() / 2**20  # MiB, as ru_maxrss / 1024


def cpu_steal_s(stat: Path = Path("/proc/stat")) -> float | None:
    """CPU time the hypervisor stole from this machine since boot, summed over its CPUs (s); None without /proc or
    on a kernel that does not count it."""
    try:
        fields = stat.read_text().split("\n", 1)[0].split()
        ticks = int(fields[8])  # cpu user nice system idle iowait irq softirq steal ...
    except (OSError, IndexError, ValueError):
        return None
    return ticks / os.sysconf("SC_CLK_TCK")


class FullCollections:
    """Counts Python's full (generation-2) garbage collections and the time they held the interpreter: one such
    collection scans every tracked object the process did not freeze, with the GIL held, in whatever thread triggered
    it, the control thread included. Installed as a `gc` callback by `start`, removed by `stop`."""

    def __init__(self) -> None:
        self.count = 0
        self.seconds = 0.0
        self._started: float | None = None

    def start(self) -> None:
        if self._callback not in gc.callbacks:
            gc.callbacks.append(self._callback)

    def stop(self) -> None:
        if self._callback in gc.callbacks:
            gc.callbacks.remove(self._callback)

    def _callback(self, phase: str, info: dict) -> None:
        if info.get("generation") != 2:
            return
        if phase == "start":
            self._started = time.perf_counter()
        elif self._started is not None:
            self.count += 1
            self.seconds += time.perf_counter() - self._started
            self._started = None
