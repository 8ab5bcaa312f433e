"""Production runs cycle by cycle, scored on the dry run's truth: the learning curve of on-cell learning beside a
frozen policy's run on the same cell.

    python -m mrguide.replay.cycle_learning LOG... --out DIR [--window 20] [--last 100]

Each log (a `deploy --dry-run --cycles` run log, with `--learn` or without) gives one curve: per cycle, whether the
part truly lay at its goal afterwards (the `scored` record a dry run writes; a robot's log has none and is refused),
its attempts, the cell's wall clock so far and the policy version of its first attempt. DIR gets `cycles.csv` (every
cycle of every log), `learning.md` (per log: cycles, parts at their goal, the same over the last `--last` cycles,
the cycles placed at their first attempt (it ended in success) over the last `--last`, the first cycle and cell
minutes at which the trailing `--last` reached 98 %, the versions tried and kept or dropped
(`policy_trial` records; none in a frozen run or one that took each version at once)) and `learning.png` (the share
at the goal over the trailing `--window` cycles, against the cell's minutes).
"""

from __future__ import annotations

import argparse
import csv
import io
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mrguide.deploy.runlog import RunLogError, read_log

TARGET = 0.98


@dataclass(frozen=True)
class Cycle:
    cycle: int
    at_goal: bool
    attempts: int
    minutes: float  # the cell's wall clock at the cycle's end, from the log's first cycle
    version: int  # the policy version of the cycle's first attempt (0: the file given; no attempt: the last before)
    first_try: bool = False  # its first attempt ended in success (the task model on the cell's sensed state)


def cycles(path: Path) -> list[Cycle]:
    """The scored cycles of one run log, in order (RunLogError if it has none)."""
    scored: dict[int, bool] = {}
    versions: list[int] = []  # per episode, in order
    ends = []
    for r in read_log(path):
        kind = r.get("kind")
        if kind == "scored":
            scored[r["cycle"]] = bool(r["at_goal"])
        elif kind == "policy_version":
            versions.append(int(r["version"]))
        elif kind == "cycle_end":
            ends.append(r)
    if not scored:
        raise RunLogError(f"{path}: no scored cycles (a dry run's `deploy --cycles` log is needed)")
    out, clock, episode = [], 0.0, 0
    for r in ends:
        clock += float(r["cycle_s"])
        version = versions[min(episode, len(versions) - 1)] if versions else 0  # a cycle with no attempt: the last
        first = r["outcomes"][:1] == ["success"]
        out.append(Cycle(r["cycle"], scored.get(r["cycle"], False), len(r["outcomes"]), clock / 60.0, version, first))
        episode += len(r["outcomes"])
    return out


def trials(path: Path) -> str:
    """The versions tried on the cell, kept and dropped ("kept / dropped"; "—" for a log without trials)."""
    verdicts = [r["verdict"] for r in read_log(path) if r.get("kind") == "policy_trial"]
    return f"{verdicts.count('kept')} / {verdicts.count('dropped')}" if verdicts else "—"


def trailing(rows: list[Cycle], n: int) -> np.ndarray:
    """The share at the goal over the trailing `n` cycles (fewer at the start), per cycle."""
    hits = np.array([c.at_goal for c in rows], dtype=float)
    sums = np.cumsum(hits)
    counts = np.minimum(np.arange(1, len(hits) + 1), n)
    return (sums - np.concatenate([np.zeros(n), sums[:-n]])[: len(sums)]) / counts


def summary_line(name: str, rows: list[Cycle], last: int, tried: str = "—") -> str:
    """One row of learning.md."""
    placed = sum(c.at_goal for c in rows)
    tail = rows[-last:]
    share = trailing(rows, last)
    reached = [i for i in range(last - 1, len(rows)) if share[i] >= TARGET]
    when = f"cycle {rows[reached[0]].cycle}, {rows[reached[0]].minutes:.1f} min" if reached else "not reached"
    tail_placed, tail_first = sum(c.at_goal for c in tail), sum(c.first_try for c in tail)
    return (
        f"| {name} | {len(rows)} | {placed} ({placed / len(rows):.0%}) | {tail_placed} / {len(tail)} "
        f"| {tail_first} / {len(tail)} | {when} | {rows[-1].minutes:.1f} | {rows[-1].version} | {tried} |"
    )


def write(logs: list[Path], out: Path, window: int, last: int) -> str:
    """cycles.csv, learning.md and learning.png in `out`; the markdown table."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    table = [
        f"| run log | cycles | at the goal | over the last {last} | at the first attempt, last {last} "
        f"| trailing {last} ≥ {TARGET:.0%} from | cell minutes | last version | versions kept / dropped |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    buf = io.StringIO()
    writer = csv.writer(buf)
    writer.writerow(["log", "cycle", "at_goal", "attempts", "minutes", "version"])
    fig, ax = plt.subplots(figsize=(7, 4))
    for path in logs:
        rows = cycles(path)
        table.append(summary_line(path.name, rows, last, trials(path)))
        writer.writerows([path.name, c.cycle, int(c.at_goal), c.attempts, f"{c.minutes:.3f}", c.version] for c in rows)
        ax.plot([c.minutes for c in rows], trailing(rows, window), label=path.name)
    ax.set_xlabel("cell time (min)")
    ax.set_ylabel(f"parts at their goal, last {window} cycles")
    ax.set_ylim(0.0, 1.02)
    ax.axhline(TARGET, color="grey", linestyle=":")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "learning.png", dpi=120)
    plt.close(fig)
    (out / "cycles.csv").write_text(buf.getvalue())
    text = "\n".join(table) + "\n"
    (out / "learning.md").write_text(text)
    return text


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mrguide.replay.cycle_learning", description=__doc__.split("\n")[0])
    ap.add_argument("logs", nargs="+", type=Path, help="dry-run cycle logs (.jsonl or .jsonl.gz)")
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--window", type=int, default=20, help="cycles of the plotted trailing share (default 20)")
    ap.add_argument("--last", type=int, default=100, help="cycles of the summary's trailing share (default 100)")
    args = ap.parse_args(argv)
    if args.window < 1 or args.last < 1:
        print("error: --window and --last must be at least 1", file=sys.stderr)
        return 2
    try:
        print(write(args.logs, args.out, args.window, args.last), end="")
    except (OSError, RunLogError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
