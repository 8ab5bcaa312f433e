"""Grasp offsets by outcome, from the CSV that `python -m mrguide.replay.failures LOG... --grasps FILE.csv` writes:
for each group of its rows (those whose log name contains the group's text), per outcome, how many episodes, the
median, 90th percentile and largest offset of the part from the cup's axis as the lift began, and how many beyond
`EDGE_MM` (about the MuJoCo cup's play: its lip seals whole on the part's face within it).

    python -m mrguide.replay.grasp_offsets FILE.csv --group TEXT [--group TEXT ...]
"""

from __future__ import annotations

import argparse
import csv
import sys
from pathlib import Path

import numpy as np

#: mm: a grasp further off the part's centre than this sits at the edge of the MuJoCo cup's seal.
EDGE_MM = 5.0


def summary(rows: list[dict[str, str]], group: str) -> list[str]:
    """One line per outcome of the rows whose log name contains `group`."""
    chosen = [r for r in rows if group in r["log"]]
    lines = []
    for outcome in sorted({r["outcome"] for r in chosen}):
        mm = np.array([float(r["grasp_offset_mm"]) for r in chosen if r["outcome"] == outcome])
        lines.append(
            f"{group} {outcome}: {len(mm)} episodes, median {np.median(mm):.1f}, p90 {np.percentile(mm, 90):.1f}, "
            f"max {mm.max():.1f} mm; {int((mm > EDGE_MM).sum())} beyond {EDGE_MM:g} mm"
        )
    return lines


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mrguide.replay.grasp_offsets", description=__doc__.split("\n")[0])
    ap.add_argument("csv", type=Path, help="a grasps CSV of `python -m mrguide.replay.failures --grasps`")
    ap.add_argument("--group", action="append", required=True, help="text of the log names of a group; repeatable")
    args = ap.parse_args(argv)
    try:
        with args.csv.open(newline="") as fh:
            rows = list(csv.DictReader(fh))
        lines = [line for g in args.group for line in summary(rows, g)]
    except (OSError, KeyError, ValueError) as exc:
        print(f"error: {args.csv}: not a grasps CSV ({exc})", file=sys.stderr)
        return 1
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
