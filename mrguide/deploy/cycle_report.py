"""`mrguide cycles report`: the figures of production runs, recomputed from their run logs, and slim copies of the
logs for the results (every cycle, retry and alarm record; every decision of the attempts that failed)."""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path
from typing import Any

import numpy as np

from mrguide.deploy.episode import MAX_CELL_BACKLOG_S
from mrguide.deploy.host_stats import MISS_ANATOMY, anatomy_value
from mrguide.deploy.runlog import RunLogError, read_log, slim_records, write_gzipped
from mrguide.errors import InputError

#: Cycles a session runs before its resident set is taken as the baseline of "RSS growth after warm-up": the
#: allocator's pools, the camera's frame buffers and the run log's buffers fill in the first cycles, a leak goes on.
WARMUP_CYCLES = 100


def rss_growth_after_warmup(records: list[dict]) -> float | None:
    """The largest growth of the resident set (MB) from a session's cycle WARMUP_CYCLES to its last cycle, over the
    log's sessions (a `run` record starts one); None if no session ran more cycles than that with `rss_mb` logged."""
    growth: list[float] = []
    rss: list[float] = []
    for r in [*records, {"kind": "run"}]:
        if r.get("kind") == "run":
            if len(rss) > WARMUP_CYCLES:
                growth.append(rss[-1] - rss[WARMUP_CYCLES - 1])
            rss = []
        elif r.get("kind") == "cycle_end" and isinstance(r.get("rss_mb"), int | float):
            rss.append(float(r["rss_mb"]))
    return max(growth) if growth else None


#: cycle_end's counters that tell a missed control cycle's cause apart: how the report names each, and how much of it
#: a production cycle must count to have it — a control cycle's work running past the period; the host stealing at
#: least 0.1 s of CPU time (the kernel counts steal in 10 ms ticks, and a tick or two is every cycle's); some task
#: waiting at least 10 ms for I/O; a page read from disk.
MISS_CONTEXT = {
    "work_overruns": ("work overruns", 1),
    "steal_s": ("host steal >= 0.1 s", 0.1),
    "io_stall_s": ("I/O stall >= 10 ms", 0.01),
    "major_faults": ("major page faults", 1),
}


def cycle_figures(records: list[dict]) -> dict[str, Any]:
    """A production run's figures from its records (a resumed run's segments together)."""
    ends = [r for r in records if r.get("kind") == "cycle_end"]
    if not ends:
        raise InputError("a run log without production cycles (no cycle_end record)")
    segments = [r for r in records if r.get("kind") == "cycles_end"]
    placed = [r for r in ends if r["placed"]]
    # the wall time is the ended segments': the parts per hour count only their cycles (a live or killed session's
    # cycles have no wall time yet)
    last_end = max((i for i, r in enumerate(records) if r.get("kind") == "cycles_end"), default=-1)
    placed_in_ended = sum(1 for r in records[:last_end] if r.get("kind") == "cycle_end" and r["placed"])
    times = np.array([r["cycle_s"] for r in placed])
    wall = sum(float(s.get("wall_s") or 0.0) for s in segments)
    return {
        "cycles": len(ends),
        "placed": len(placed),
        "placed_first_attempt": sum(r["outcomes"] == ["success"] for r in placed),
        # placed by an attempt that failed as it set the part down (`placed_on_check`): no attempt ended in success
        "placed_on_check": sum("success" not in r["outcomes"] for r in placed),
        "alarms": sum(r["alarm"] is not None for r in ends),
        # a cycle ends unplaced without an alarm only when the run stopped in it (a safety stop, Ctrl-C twice)
        "cut": sum(not r["placed"] and r["alarm"] is None for r in ends),
        "retries": dict(Counter(c for r in ends for c in r["retries"])),
        "cells_behind": _cells_behind(records),
        "cycle_s_median": float(np.median(times)) if len(times) else None,
        "cycle_s_p95": float(np.percentile(times, 95)) if len(times) else None,
        "parts_per_hour": 3600.0 * placed_in_ended / wall if wall > 0 else None,
        # the driver's counters are in the run's summary record(s): unknown for a run that ended without one
        "missed_cycles": sum(int(s["missed_cycles"]) for s in segments) if segments else None,
        "underruns": sum(int(s["underruns"]) for s in segments) if segments else None,
        "rss_growth_mb": max(float(s["rss_growth_mb"]) for s in segments) if segments else None,
        "rss_growth_after_warmup_mb": rss_growth_after_warmup(records),
        "cycles_with_missed": _cycles_with(ends, "missed_cycles"),
        **{f"cycles_with_{key}": _cycles_with(ends, key) for key in MISS_CONTEXT},
        **{f"cycles_with_missed_and_{key}": _cycles_with(ends, "missed_cycles", key) for key in MISS_CONTEXT},
        **{f"missed_with_{key}": _missed_with(ends, key) for key in MISS_CONTEXT},
    }


def _cells_behind(records: list[dict]) -> int | None:
    """How many cycles of a dry run its simulated cell played more than MAX_CELL_BACKLOG_S behind the clock (the
    `scored` records); None for a log that does not record it (a robot's, or a dry run's from before)."""
    scored = [r for r in records if r.get("kind") == "scored" and "cell_backlog_s" in r]
    return sum(float(r["cell_backlog_s"]) > MAX_CELL_BACKLOG_S for r in scored) if scored else None


def _cycles_with(ends: list[dict], *keys: str) -> int | None:
    """How many production cycles counted, of every cycle_end counter in `keys`, at least its MISS_CONTEXT amount
    (any, for a counter not in it); None unless every cycle_end records them (logs from before they were)."""
    if not all(isinstance(r.get(k), int | float) for r in ends for k in keys):
        return None
    least = {k: MISS_CONTEXT[k][1] if k in MISS_CONTEXT else 1 for k in keys}
    return sum(all(r[k] >= least[k] for k in keys) for r in ends)


def _missed_with(ends: list[dict], key: str) -> int | None:
    """How many control cycles were missed in the production cycles that counted at least `key`'s MISS_CONTEXT
    amount; None unless every cycle_end records both."""
    if not all(isinstance(r.get(k), int | float) for r in ends for k in ("missed_cycles", key)):
        return None
    return sum(int(r["missed_cycles"]) for r in ends if r[key] >= MISS_CONTEXT[key][1])


def table(rows: dict[str, dict[str, Any]]) -> str:
    """One markdown row per run."""
    head = (
        "| run | parts placed | without alarm | first attempt | retries (cause) | alarms | cycle time median / p95 "
        "| parts per hour | missed control cycles | queue ran dry | peak RSS growth | RSS growth after warm-up |"
    )
    lines = [head, "| " + " | ".join(["---"] * (head.count("|") - 1)) + " |"]
    for name, f in rows.items():
        n = f["cycles"]
        retries = ", ".join(f"{k} {v}" for k, v in sorted(f["retries"].items())) or "none"
        lines.append(
            f"| {name} | {f['placed']} / {n}{f' ({cut} cut by a stop)' if (cut := f['cut']) else ''}{_on_check(f)}{_behind(f)} "
            f"| {(n - f['alarms']) / n:.1%} | {f['placed_first_attempt']} | {retries} "
            f"| {f['alarms']} | {_num(f['cycle_s_median'], '.2f')} / {_num(f['cycle_s_p95'], '.2f')} s "
            f"| {_num(f['parts_per_hour'], '.0f')} | {_num(f['missed_cycles'], 'd')}{_in_cycles(f)} | {_num(f['underruns'], 'd')} "
            f"| {_num(f['rss_growth_mb'], '.1f', ' MB')} | {_num(f['rss_growth_after_warmup_mb'], '.1f', ' MB')} |"
        )
    return "\n".join(lines) + "\n"


#: The anatomy's fields that logs from before them lack (the report writes "—" for them there).
LATER_ANATOMY = ("miss_slices", "miss_collections", "miss_collecting_s")


def miss_anatomy(records: list[dict]) -> dict[str, float | None] | None:
    """A run's gaps that skipped deadlines, summed over its production cycles by where the control thread's time
    went; None unless every cycle_end records them (logs from before they were, or a host without /proc). The
    LATER_ANATOMY fields are None in logs from before they were recorded."""
    ends = [r for r in records if r.get("kind") == "cycle_end"]
    required = [k for k in MISS_ANATOMY if k not in LATER_ANATOMY]
    if not ends or not all(isinstance(r.get(k), int | float) for r in ends for k in required):
        return None
    return {
        k: sum(float(r[k]) for r in ends) if all(isinstance(r.get(k), int | float) for r in ends) else None
        for k in MISS_ANATOMY
    }


def anatomy_table(rows: dict[str, dict[str, float | None]]) -> str:
    """One markdown row per run that records where its missed gaps' time went (s)."""
    head = "| run | " + " | ".join(MISS_ANATOMY.values()) + " |"
    lines = [head, "| " + " | ".join(["---"] * (len(MISS_ANATOMY) + 1)) + " |"]
    for name, a in rows.items():
        cells = [anatomy_value(k, a[k]) for k in MISS_ANATOMY]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def _in_cycles(f: dict[str, Any]) -> str:
    """Where a run's missed control cycles fell: in how many production cycles, how many of those counted each of
    MISS_CONTEXT that the log records, [in brackets] how many of all the run's cycles did (a context as common in every
    cycle as in those with a miss does not explain it), and (in parentheses) how many control cycles were missed in the
    cycles with it."""
    if f["cycles_with_missed"] is None:
        return ""
    events = [
        f"{f[f'cycles_with_missed_and_{key}']} with {name} [{f[f'cycles_with_{key}']}] "
        f"({f[f'missed_with_{key}']} missed)"
        for key, (name, _) in MISS_CONTEXT.items()
        if f[f"cycles_with_missed_and_{key}"] is not None
    ]
    return f" (in {f['cycles_with_missed']} cycles" + (": " + ", ".join(events) if events else "") + ")"


def _on_check(f: dict[str, Any]) -> str:
    """The parts placed by an attempt that failed as it set them down, if any."""
    k = f["placed_on_check"]
    return f" ({k} seen at the goal after a failed attempt)" if k else ""


def _behind(f: dict[str, Any]) -> str:
    """A dry run's cycles its cell played behind the clock, if any (not cycles a cell on time would have played)."""
    k = f["cells_behind"]
    return f" ({k} with the simulated cell > {MAX_CELL_BACKLOG_S:g} s behind the clock)" if k else ""


def _num(value: float | int | None, fmt: str, unit: str = "") -> str:
    """A figure and its unit, or "—" where the log does not have it (a run that ended without its summary record, a
    log from before the figure was recorded)."""
    return "—" if value is None else format(value, fmt) + unit


def add_cycles_command(sub: argparse._SubParsersAction) -> None:
    sp = sub.add_parser("cycles", help="production runs (deploy --cycles): their figures from the run logs")
    kinds = sp.add_subparsers(dest="cycles_command", required=True)
    rp = kinds.add_parser("report", help="a table of production runs, recomputed from their run logs")
    rp.add_argument("logs", nargs="+", help="run logs of `deploy --cycles` (.jsonl or .jsonl.gz)")
    rp.add_argument(
        "--out",
        help="also write cycles.md and slim gzipped copies of the logs into this folder (logs already in it stay)",
    )
    rp.set_defaults(func=cmd_cycles_report)


def cmd_cycles_report(args: argparse.Namespace) -> int:
    rows, anatomies = {}, {}
    for path in map(Path, args.logs):
        name = path.name.removesuffix(".gz").removesuffix(".jsonl")
        records = read_log(path)
        try:
            rows[name] = cycle_figures(records)
        except InputError as exc:
            raise RunLogError(f"{path}: {exc}") from exc
        anatomy = miss_anatomy(records)
        if anatomy is not None:
            anatomies[name] = anatomy
        if args.out:
            out = Path(args.out)
            out.mkdir(parents=True, exist_ok=True)
            if path.resolve().parent != out.resolve():  # a published log is not slimmed again by a newer rule
                write_gzipped(out / f"{name}.jsonl.gz", slim_records(records))
    md = table(rows)
    if anatomies:
        md += "\nWhere the control thread's time went in the gaps that skipped deadlines:\n\n" + anatomy_table(
            anatomies
        )
    if args.out:
        (Path(args.out) / "cycles.md").write_text(md)
    print(md, end="")
    return 0
