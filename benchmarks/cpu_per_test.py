"""A pytest plugin: the CPU seconds each test costs, to find what makes the README's test command slow.

    CPU_LOG=/tmp/cpu.log PYTHONPATH=benchmarks .venv/bin/python -m pytest -q -n 2 -m "not slow and realtime" \
        -p cpu_per_test
    sort -rn /tmp/cpu.log | head        # CPU s, wall s, start, worker, node id; one line per test

CPU is the test process's own (all its threads) plus that of the child processes it waited for, around the test's
whole protocol (setup, call, teardown); its start is the machine's monotonic clock (s), shared by the xdist
workers, so that the lines show how the workers' time was spent. What a test's helpers leave running (Chromium's GPU process under
playwright's driver, Ray's daemons) is not in it: measure those with /proc/stat around a run of their tests.
"""

from __future__ import annotations

import os
import resource
import time
from collections.abc import Generator

import pytest


def _cpu_s() -> float:
    own, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + children.ru_utime + children.ru_stime


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item: pytest.Item, nextitem: pytest.Item | None) -> Generator[None, None, None]:
    """Append "CPU s, wall s, start, worker, node id" of `item` to $CPU_LOG."""
    cpu, wall = _cpu_s(), time.monotonic()
    yield
    with open(os.environ["CPU_LOG"], "a") as fh:
        worker = os.environ.get("PYTEST_XDIST_WORKER", "main")
        fh.write(f"{_cpu_s() - cpu:.2f} {time.monotonic() - wall:.2f} {wall:.2f} {worker} {item.nodeid}\n")
