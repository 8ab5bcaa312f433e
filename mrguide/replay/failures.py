"""The failed episodes of run logs, one line each: the outcome, the phase it ended in, the vacuum level and TCP
height over its last decisions — where a part was lost, and whether the seal broke at once or leaked away — and
how far the part was pushed across the table before the cup held it, and how far off the cup's axis it hung when the
lift began (a simulated cell's ground truth). A dry run's episode whose simulated cell ran more than 0.1 s behind the
clock (its `cell_backlog` record) is marked: `mrguide sim2real` does not judge it.

    python -m mrguide.replay.failures LOG... [--grasps FILE.csv]

Prints a line per failed episode and, per log, the outcomes of all its episodes. A slim log (`runlog_slim`) keeps
every failed episode's decisions. `--grasps` also writes, for every episode that holds its decisions (all of them
in a full log), the part's offset from the TCP at the lift's first decision, each row naming its log as given (give
paths that tell runs apart: Fig. 8's logs share their names across policies). Replay the failures with `mrguide
replay LOG --outcome dropped --save drops.rrd`.
"""

from __future__ import annotations

import argparse
import csv
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from mrguide.deploy.episode import MAX_CELL_BACKLOG_S
from mrguide.deploy.runlog import read_log
from mrguide.replay.runs import Episode, RunError, load_run
from mrguide.task import Phase

#: Decisions at the end of a failed episode that its line shows.
TAIL = 5
#: mm: a part that got this far before the grasp was pushed (a look's noise is no push: the truth does not move).
PUSHED = 3.0


def failure_line(ep: Episode) -> str:
    """`ep`'s outcome, the phase of its last decision, and its last vacuum levels (kPa) and TCP heights (mm)."""
    frames = ep.frames[-TAIL:]
    phase = Phase(frames[-1].phase).name.lower() if frames else "?"
    vacuum = " ".join("?" if f.vacuum_kpa is None else f"{f.vacuum_kpa:.0f}" for f in frames)
    height = " ".join("?" if f.tcp is None else f"{1e3 * f.tcp[2]:.0f}" for f in frames)
    offset, pushed = grasp_offset_mm(ep), pushed_mm(ep)
    push = "" if pushed is None or pushed < PUSHED else f"; the part pushed {pushed:.0f} mm before the cup held it"
    off = "" if offset is None else f"; the part {offset:.1f} mm off the cup's axis as the lift began"
    return f"{ep.label}: {ep.outcome} in {phase}; vacuum {vacuum} kPa; TCP z {height} mm{push}{off}"


def pushed_mm(ep: Episode) -> float | None:
    """How far (mm, ground truth, laterally) the part got from where it lay at the start before the cup held it (the
    approach and the grasp, the part not reported held), if the log knows where it was."""
    before = [f.obj_true for f in ep.frames if f.phase <= Phase.GRASP and not f.part and f.obj_true is not None]
    if not before:
        return None
    return float(1e3 * max(np.linalg.norm((p - before[0])[:2]) for p in before))


def grasp_offset_mm(ep: Episode) -> float | None:
    """The part's lateral distance from the TCP (mm, ground truth) at the episode's first lift decision, if known."""
    lift = next((f for f in ep.frames if f.phase == Phase.LIFT), None)
    if lift is None or lift.obj_true is None or lift.tcp is None:
        return None
    return float(1e3 * np.linalg.norm((lift.obj_true - lift.tcp)[:2]))


def cells_behind(path: str) -> dict[int, float]:
    """The episodes of a dry run's log whose simulated cell ran more than MAX_CELL_BACKLOG_S behind the clock, and by
    how much (s); none for a log that does not record it."""
    records = (r for r in read_log(path) if r.get("kind") == "cell_backlog" and "episode" in r)
    seconds = {r["episode"]: float(r["seconds"]) for r in records}
    return {e: s for e, s in seconds.items() if s > MAX_CELL_BACKLOG_S}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mrguide.replay.failures", description=__doc__.split("\n")[0])
    ap.add_argument("logs", nargs="+", help="run logs (.jsonl or .jsonl.gz) of deploy, a dry run or sim2real")
    ap.add_argument("--grasps", type=Path, help="write every episode's grasp offset to this CSV")
    args = ap.parse_args(argv)
    rows = []
    for path in args.logs:
        try:
            episodes = load_run(path)
        except RunError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        behind = cells_behind(path)
        for ep in episodes:
            if ep.outcome != "success":
                late = (
                    f"; the cell ran {behind[ep.index]:.2f} s behind the clock: not judged"
                    if ep.index in behind
                    else ""
                )
                print(failure_line(ep) + late)
            offset = grasp_offset_mm(ep)
            if offset is not None:
                rows.append(
                    {
                        "log": str(path),
                        "episode": ep.index,
                        "outcome": ep.outcome,
                        "grasp_offset_mm": round(offset, 2),
                    }
                )
        outcomes = Counter(str(ep.outcome) for ep in episodes)
        late = f"; {len(behind)} with the cell behind the clock (not judged)" if behind else ""
        print(f"{path}: {len(episodes)} episodes, " + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())) + late)
    if args.grasps:
        with args.grasps.open("w", newline="") as fh:
            writer = csv.DictWriter(fh, ["log", "episode", "outcome", "grasp_offset_mm"])
            writer.writeheader()
            writer.writerows(rows)
    return 0


if __name__ == "__main__":
    sys.exit(main())
