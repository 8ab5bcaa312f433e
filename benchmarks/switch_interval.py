"""Missed control cycles at Python's default thread switch interval and at a shorter one: alternating pairs.

Run: python benchmarks/switch_interval.py --policy docs/results/sim2real-main5k/policy.npz [--interval S]
[--cycles N] [--pairs P] [--cell ...] [--logs DIR]. Each pair runs `--cycles` production cycles of the policy (the
same feeder seed: the same parts and goals) with the simulated cell in a process of its own, as `mrguide deploy
--dry-run` runs it, first with the bus config's `timing.switch_interval` = 0 (the interpreter's 5 ms) and then with
`--interval`. Per run: missed control cycles, work overruns, dry setpoint queues, host steal, the median cycle time,
and where the control thread's time went in the gaps that skipped deadlines (on a CPU, waiting for one, off one
unasked: the GIL, I/O or the host). Run it on a quiet machine. The last line is one JSON object.
"""

from __future__ import annotations

import json
import tempfile
from dataclasses import replace
from pathlib import Path
from typing import Any

from cell_process import pair_parser, print_header, print_row, run

from mrguide.cli_args import positive_float
from mrguide.deploy.host_stats import miss_anatomy_text
from mrguide.experiments.sim2real import load_real_cell


def print_anatomy(r: dict[str, Any]) -> None:
    """Where the control thread's time went in the run's gaps that skipped deadlines (none recorded: nothing)."""
    if r.get("miss_gaps"):
        print("        " + miss_anatomy_text(r), flush=True)


def main() -> None:
    ap = pair_parser(__doc__, 30, 4, "PAIR-INTERVAL.jsonl")
    ap.add_argument("--interval", type=positive_float, default=0.0005, help="the shorter switch interval (s)")
    args = ap.parse_args()
    cell = load_real_cell(args.cell)
    print_header(args.cell)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        logs = args.logs or Path(tmp)
        logs.mkdir(parents=True, exist_ok=True)
        for pair in range(args.pairs):
            for interval in (0.0, args.interval):
                bus = replace(cell.bus, timing=replace(cell.bus.timing, switch_interval=interval))
                log = logs / f"{pair}-{interval * 1000:g}ms.jsonl"
                row = run(args.policy, cell, args.cycles, args.seed, True, log, bus)
                rows.append({"switch_interval": interval, **row})
                print(f"switch interval {interval * 1000:g} ms (0: the interpreter's)")
                print_row(row)
                print_anatomy(row)
    print(json.dumps({"policy": args.policy, "cell": args.cell.name, "cycles": args.cycles, "runs": rows}))


if __name__ == "__main__":
    main()
