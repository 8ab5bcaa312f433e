"""What the process and its host spent, for the production logs: memory, the CPU time a hypervisor took, and what
held the machine's tasks up.

Linux only (/proc); elsewhere the readings are None. A virtual machine's "steal" time is time its virtual CPUs were
ready to run and the host ran something else: no priority inside the guest gets it back, so a control cycle missed
while the host stole is told apart from one the process missed itself. The kernel's pressure stall information
(/proc/pressure) says how long some task waited for a CPU or for I/O; the process's major page faults (a page read
from disk, with whatever lock the faulting thread held) and involuntary context switches (a thread put off a CPU for
another) say what happened to this process.
"""

from __future__ import annotations

import gc
import operator
import os
import resource
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from mrguide.drivers.thread_clock import if_known


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


def pressure_stall_s(resource_name: str, root: Path = Path("/proc/pressure")) -> float | None:
    """Total time since boot that some task waited for `resource_name` ("cpu", "io" or "memory") (s), from the
    kernel's pressure stall information; None where the kernel does not provide it."""
    try:
        some = (root / resource_name).read_text().split("\n", 1)[0].split()
        if some[0] != "some":
            return None
        return int(dict(f.split("=", 1) for f in some[1:])["total"]) / 1e6  # µs
    except (OSError, IndexError, KeyError, ValueError):
        return None


@dataclass(frozen=True)
class HostCounters:
    """Counters of the host and the process at one moment; `since` turns two of them into a cycle's record."""

    steal_s: float | None
    cpu_stall_s: float | None
    io_stall_s: float | None
    major_faults: int
    preemptions: int

    @classmethod
    def now(cls) -> HostCounters:
        usage = resource.getrusage(resource.RUSAGE_SELF)
        return cls(cpu_steal_s(), pressure_stall_s("cpu"), pressure_stall_s("io"), usage.ru_majflt, usage.ru_nivcsw)

    def since(self, earlier: HostCounters) -> dict[str, float | int | None]:
        """What happened between `earlier` and this reading, by field (None where either reading is missing)."""
        return {
            "steal_s": if_known(operator.sub, self.steal_s, earlier.steal_s),
            "cpu_stall_s": if_known(operator.sub, self.cpu_stall_s, earlier.cpu_stall_s),
            "io_stall_s": if_known(operator.sub, self.io_stall_s, earlier.io_stall_s),
            "major_faults": self.major_faults - earlier.major_faults,
            "preemptions": self.preemptions - earlier.preemptions,
        }


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


#: The fields of `MissAnatomy.since` in a cycle record: where the control thread's time went in the gaps between
#: control cycle starts that skipped deadlines, and how the summary line and `mrguide cycles report` name them.
MISS_ANATOMY = {
    "miss_gaps": "gaps that skipped deadlines",
    "miss_wall_s": "their time",
    "miss_cpu_s": "on a CPU",
    "miss_runq_s": "waiting for a CPU",
    "miss_off_cpu_s": "off a CPU unasked (GIL, I/O, host)",
    "miss_slept_s": "asleep as planned",
    "miss_slices": "times put on a CPU",
    "miss_collections": "garbage collections in the control thread",
    "miss_collecting_s": "their time",
}


def anatomy_value(key: str, value: float | None) -> str:
    """One of MISS_ANATOMY's figures as the report writes it ("—": not recorded)."""
    if value is None:
        return "—"
    return f"{value:.3f} s" if key.endswith("_s") else f"{value:.0f}"


def miss_anatomy_text(misses: Mapping[str, Any]) -> str:
    """One line on the control thread's gaps that skipped deadlines (MISS_ANATOMY's fields; those not recorded are
    left out)."""
    return ", ".join(
        f"{label}: {anatomy_value(key, misses[key])}"
        for key, label in MISS_ANATOMY.items()
        if misses.get(key) is not None
    )
