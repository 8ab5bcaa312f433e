"""The host's late wake-ups: a thread that only sleeps to the control period's deadlines, in a process of its own.

Run: python benchmarks/host_wakeups.py probe --seconds S --out F.jsonl [--period P] [--priority N] [--cyclictest]
     python benchmarks/host_wakeups.py match F.jsonl LOG...

`probe` runs the control loop's timer (`mrguide.drivers.cycle.CycleTimer`: absolute deadlines on `time.monotonic`)
at SCHED_FIFO `--priority` in one process per CPU, each pinned to its CPU and with no other thread: no GIL to wait
for and no work, so a deadline it skips is the host's (its timers, the hypervisor's scheduling of that virtual CPU).
It writes one record per wake-up a period or more late (which CPU, when, how late, deadlines skipped) and a summary.
With `--cyclictest` it also runs rt-tests' cyclictest (C, memory locked, one thread per CPU) for as long at the same
period and priority: the same measure without Python.

`match` reads the run logs of `mrguide deploy --cycles` made while the probe ran and says how many of the control
thread's gaps that skipped deadlines (their `miss_at` records) overlap a late wake-up of the probe, beside how many
would by chance. The last line of each command is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import platform
import shutil
import statistics
import subprocess
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

from mrguide.cli_args import positive_float, positive_int
from mrguide.deploy.runlog import read_log
from mrguide.drivers.cycle import CycleTimer
from mrguide.drivers.realtime import make_current_thread_realtime


def run_probe(cpu: int, seconds: float, period: float, priority: int) -> tuple[dict[str, Any], list[dict[str, Any]]]:
    """On `cpu`, sleep to successive deadlines for `seconds`; the header and the late wake-ups."""
    os.sched_setaffinity(0, {cpu})
    realtime = make_current_thread_realtime(priority)
    timer = CycleTimer(period)
    late: list[dict[str, Any]] = []
    ticks = 0
    timer.start()
    start = time.monotonic()
    head = {"kind": "probe", "cpu": cpu, "period": period, "priority": priority, "realtime": realtime}
    while time.monotonic() - start < seconds:
        tick = timer.wait()
        now = time.monotonic()
        ticks += 1
        if tick.skipped:
            due = tick.deadline - tick.skipped * period  # the deadline it woke up for
            late.append({"kind": "late", "cpu": cpu, "at": now, "late_s": now - due, "skipped": tick.skipped})
    head |= {"started": start, "ended": time.monotonic(), "ticks": ticks}
    return head, late


def start_cyclictest(seconds: float, period: float, priority: int, histfile: Path) -> subprocess.Popen | None:
    """rt-tests' cyclictest for `seconds` at `period` and `priority`, its histogram to `histfile`; None if absent."""
    exe = shutil.which("cyclictest")
    if exe is None:
        print("cyclictest not found (Debian: apt install rt-tests): the probe runs alone", flush=True)
        return None
    interval_us = round(period * 1e6)
    args = [exe, "-m", "-q", "-a", "-t", "-p", str(priority), "-i", str(interval_us), "-D", f"{int(seconds)}s"]
    args += ["-h", str(10 * interval_us), f"--histfile={histfile}"]
    return subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)


def cyclictest_figures(histfile: Path, period: float) -> dict[str, Any]:
    """Wake-ups measured, how many came a period or more late (the histogram's overflows included), the largest; over
    all of its threads."""
    late = 0
    header: dict[str, list[int]] = {}
    for line in histfile.read_text().splitlines():
        if line.startswith("#") and ":" in line:
            key, _, value = line[1:].partition(":")
            header[key.strip()] = [int(v) for v in value.split() if v.isdigit()]
        elif line and not line.startswith("#"):
            us, *counts = (int(v) for v in line.split())
            late += sum(counts) if us >= period * 1e6 else 0
    return {
        "wakeups": sum(header.get("Total", [])),
        "late": late + sum(header.get("Histogram Overflows", [])),
        "max_late_s": max(header.get("Max Latencies", [0])) / 1e6,
    }


def summary(
    heads: list[dict[str, Any]], late: list[dict[str, Any]], cyclictest: dict[str, Any] | None
) -> dict[str, Any]:
    hours = (max(h["ended"] for h in heads) - min(h["started"] for h in heads)) / 3600
    return {
        "kind": "summary",
        "host": platform.node(),
        "cpus": os.cpu_count(),
        "seconds": round(hours * 3600, 1),
        "realtime": all(h["realtime"] for h in heads),
        "wakeups": sum(h["ticks"] for h in heads),
        "late_wakeups": len(late),
        "skipped": sum(r["skipped"] for r in late),
        "late_per_hour": round(len(late) / hours, 1) if hours else None,
        "max_late_s": max((r["late_s"] for r in late), default=0.0),
        "cyclictest": cyclictest,
    }


def cmd_probe(args: argparse.Namespace) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        hist = Path(tmp) / "cyclictest.hist"
        ct = start_cyclictest(args.seconds, args.period, args.priority, hist) if args.cyclictest else None
        cpus = sorted(os.sched_getaffinity(0))
        n = len(cpus)
        with ProcessPoolExecutor(n, mp_context=multiprocessing.get_context("fork")) as pool:
            probes = list(pool.map(run_probe, cpus, [args.seconds] * n, [args.period] * n, [args.priority] * n))
        heads = [head for head, _ in probes]
        late = sorted((r for _, records in probes for r in records), key=lambda r: r["at"])
        figures = None
        if ct is not None:
            _, err = ct.communicate()
            figures = cyclictest_figures(hist, args.period) if hist.exists() else {"error": err.strip()[-300:]}
    result = summary(heads, late, figures)
    with open(args.out, "w") as f:
        for record in (*heads, *late, result):
            f.write(json.dumps(record) + "\n")
    print(
        f"probe on {len(heads)} CPUs: {result['wakeups']} wake-ups in {result['seconds']} s at {args.period * 1e3:g} "
        f"ms, SCHED_FIFO {args.priority if result['realtime'] else '(refused)'}: {result['late_wakeups']} a period or more late "
        f"({result['late_per_hour']} per hour), the latest {result['max_late_s'] * 1e3:.1f} ms late"
    )
    if figures and "late" in figures:
        print(
            f"cyclictest: {figures['wakeups']} wake-ups, {figures['late']} a period or more late, the latest "
            f"{figures['max_late_s'] * 1e3:.1f} ms"
        )
    print(json.dumps(result))


def deploy_gaps(logs: list[str]) -> list[tuple[float, float, int]]:
    """(start, end, deadlines skipped) of every gap the logs' cycle_end records list, on time.monotonic()."""
    gaps = []
    for path in logs:
        for r in read_log(Path(path)):
            if r.get("kind") == "cycle_end":
                gaps += [(end - length, end, int(skipped)) for end, length, skipped in r.get("miss_at", [])]
    return gaps


def cmd_match(args: argparse.Namespace) -> None:
    records = read_log(args.probe)  # JSON lines, gzipped or not
    heads = [r for r in records if r["kind"] == "probe"]
    started, ended = max(h["started"] for h in heads), min(h["ended"] for h in heads)
    late = [(r["at"] - r["late_s"], r["at"]) for r in records if r["kind"] == "late"]
    span = ended - started
    gaps = [g for g in deploy_gaps(args.logs) if started <= g[0] and g[1] <= ended]
    matched = [g for g in gaps if any(a < g[1] and g[0] < b for a, b in late)]
    # how far apart the control thread and the nearest late probe woke up, for the matched gaps (ms)
    apart = [min(abs(b - g[1]) for a, b in late if a < g[1] and g[0] < b) * 1e3 for g in matched]
    chance = sum(min(1.0, sum(b - a + g[1] - g[0] for a, b in late) / span) for g in gaps)
    result = {
        "gaps": len(gaps),
        "missed": sum(g[2] for g in gaps),
        "gaps_matched": len(matched),
        "missed_matched": sum(g[2] for g in matched),
        "expected_by_chance": round(chance, 2),
        "woke_apart_ms_median": round(statistics.median(apart), 3) if apart else None,
        "probe_late_wakeups": len(late),
    }
    print(
        f"{result['gaps']} gaps of the control thread that skipped deadlines ({result['missed']} missed cycles) "
        f"while the probe ran; {result['gaps_matched']} of them ({result['missed_matched']} missed) overlap a late "
        f"wake-up of the probe ({len(late)} in all); by chance about {chance:.1f} would"
        + (f"; the two woke {result['woke_apart_ms_median']} ms apart (median)" if apart else "")
    )
    print(json.dumps(result))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    pp = sub.add_parser("probe", help="sleep to the period's deadlines and record the late wake-ups")
    pp.add_argument("--seconds", type=positive_float, default=600.0)
    pp.add_argument("--period", type=positive_float, default=0.004, help="s (the control period)")
    pp.add_argument("--priority", type=positive_int, default=50, help="SCHED_FIFO priority (the dry runs' 50)")
    pp.add_argument("--cyclictest", action="store_true", help="also run rt-tests' cyclictest beside it")
    pp.add_argument("--out", required=True, help="JSON lines: the header, the late wake-ups, the summary")
    pp.set_defaults(func=cmd_probe)
    mp = sub.add_parser("match", help="the deploy logs' missed gaps against the probe's late wake-ups")
    mp.add_argument("probe", help="a probe's output (.jsonl or .jsonl.gz)")
    mp.add_argument("logs", nargs="+", help="run logs of `mrguide deploy --cycles` made while it ran")
    mp.set_defaults(func=cmd_match)
    args = ap.parse_args()
    args.func(args)


if __name__ == "__main__":
    main()
