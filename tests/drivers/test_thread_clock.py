"""Where the control thread's time went in the gaps that skipped deadlines: on a CPU, waiting for one, or blocked."""

from __future__ import annotations

import gc
import sys
import threading
import time

import pytest

from mrguide.drivers.cycle import RECENT_GAPS, MissAnatomy
from mrguide.drivers.thread_clock import Gap, ThreadClock, ThreadReading

linux_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc/thread-self/schedstat is Linux's")


def test_a_gap_is_split_into_cpu_run_queue_planned_sleep_and_the_rest():
    gap = Gap.between(ThreadReading(10.0, 1.0, 0.5, 7), ThreadReading(10.1, 1.02, 0.53, 9), slept=0.004)
    assert (gap.wall, gap.cpu, gap.runq, gap.slices) == pytest.approx((0.1, 0.02, 0.03, 2))
    assert gap.off_cpu == pytest.approx(0.1 - 0.02 - 0.03 - 0.004)
    assert Gap.between(ThreadReading(0.0, 0.0, None), ThreadReading(1.0, 0.5, None), 0.0).off_cpu is None


def test_the_anatomy_sums_gaps_and_says_unknown_once_a_gap_was():
    a = MissAnatomy().add(Gap(0.012, 0.001, 0.0, 0.002, 1)).add(Gap(0.02, 0.003, 0.001, 0.006, 3))
    assert (a.gaps, a.wall_s, a.cpu_s, a.slept_s, a.runq_s) == pytest.approx((2, 0.032, 0.004, 0.001, 0.008))
    assert a.off_cpu_s == pytest.approx(0.009 + 0.01) and a.slices == 4
    since = a.add(Gap(0.01, 0.0, 0.0, 0.01, 2)).since(a)
    assert since["miss_gaps"] == 1 and since["miss_runq_s"] == pytest.approx(0.01) and since["miss_slices"] == 2
    assert since["miss_off_cpu_s"] == pytest.approx(0.0)
    unknown = a.add(Gap(0.01, 0.0, 0.0, None))
    assert unknown.runq_s is None and unknown.off_cpu_s is None and unknown.since(a)["miss_runq_s"] is None
    assert unknown.slices is None
    collected = a.add(Gap(0.03, 0.025, 0.0, 0.0, 1, collections=3, collecting=0.02))
    assert (collected.collections, collected.collecting_s) == pytest.approx((3, 0.02))
    assert collected.since(a)["miss_collections"] == 3


def test_the_anatomy_keeps_when_the_latest_gaps_ended_for_matching_another_process():
    a = MissAnatomy()
    for i in range(RECENT_GAPS + 5):
        a = a.add(Gap(0.008, 0.0, 0.004, 0.0, 1, ended=100.0 + i), skipped=1 + i % 2)
    assert len(a.recent) == RECENT_GAPS and a.recent[-1] == (100.0 + RECENT_GAPS + 4, 0.008, 1 + (RECENT_GAPS + 4) % 2)
    assert a.recent[0][0] == 105.0  # the five oldest are gone
    b = a.add(Gap(0.02, 0.0, 0.0, 0.0, 1, ended=500.0), skipped=4)
    assert b.since(a)["miss_at"] == [[500.0, 0.02, 4]]
    assert len(b.since(MissAnatomy())["miss_at"]) == RECENT_GAPS  # more gaps than kept: the latest
    assert b.since(b)["miss_at"] == []
    ended = Gap.between(ThreadReading(10.0, 1.0, 0.5, 7), ThreadReading(10.1, 1.02, 0.53, 9), slept=0.004).ended
    assert ended == 10.1


def test_a_thread_counts_its_own_garbage_collections_not_another_threads():
    readings: dict[str, int] = {}
    measured, other_done = threading.Event(), threading.Event()

    def collect_twice() -> None:
        clock = ThreadClock()
        gc.collect()  # the allocation count starts at 0: no automatic collection in what follows
        before = clock.read()
        gc.collect(0)
        gc.collect(1)
        measured.set()
        other_done.wait()  # the main thread collects meanwhile
        after = clock.read()
        readings["own"] = after.collections - before.collections
        readings["collecting"] = after.collecting >= before.collecting
        clock.close()

    collector = threading.Thread(target=collect_twice)
    collector.start()
    measured.wait()
    for _ in range(3):
        gc.collect(0)
    other_done.set()
    collector.join()
    assert readings == {"own": 2, "collecting": True}
    assert not any(getattr(cb, "__module__", "") == "mrguide.drivers.thread_clock" for cb in gc.callbacks)


@linux_only
def test_a_thread_that_computes_is_on_a_cpu_and_one_that_waits_for_a_lock_is_not():
    gaps: dict[str, Gap] = {}
    lock = threading.Lock()
    about_to_block = threading.Event()

    def spin() -> None:
        clock = ThreadClock()
        before = clock.read()
        while time.thread_time() - before.cpu < 0.05:
            pass
        gaps["spin"] = Gap.between(before, clock.read(), 0.0)
        clock.close()

    def block() -> None:
        clock = ThreadClock()
        before = clock.read()
        about_to_block.set()
        with lock:
            gaps["block"] = Gap.between(before, clock.read(), 0.0)
        clock.close()

    with lock:
        waiter = threading.Thread(target=block)
        waiter.start()
        about_to_block.wait()
        time.sleep(0.2)
    spinner = threading.Thread(target=spin)
    spinner.start()
    spinner.join()
    waiter.join()
    assert gaps["spin"].cpu >= 0.05 and gaps["spin"].runq is not None
    # the waiter's 0.2 s: blocked (or, on a busy machine, partly waiting for a CPU), hardly any of it computing
    block_gap = gaps["block"]
    assert block_gap.wall >= 0.2 and block_gap.cpu < 0.05
    assert block_gap.off_cpu is not None and block_gap.runq is not None
    assert block_gap.off_cpu + block_gap.runq >= 0.15
    assert block_gap.slices is not None and block_gap.slices >= 1  # put on a CPU again when the lock came free
