"""Missed control cycles with the simulated cell in the deploy stack's process or in its own: alternating pairs.

Run: python benchmarks/cell_process.py --policy docs/results/sim2real-main5k/policy.npz [--cycles N] [--pairs P]
[--cell ...]. Each pair runs `--cycles` production cycles of the policy (the same feeder seed: the same parts and
goals) with the simulated devices and the plant in the deploy process (python-can's virtual bus, as the tests and
the sim2real experiment run them) and then in a process of their own (the pipe link, as `mrguide deploy
--dry-run` runs them); the part's pose comes from the cell's pose source (exact, or the twin-rendered camera of
configs/cells/camera_cell.toml). Per run: missed control cycles, control cycles whose work ran past the period, the cycle
work's p99 and maximum, dry setpoint queues, host steal and the median cycle time. Run it on a quiet machine: other
work on the two cores says more about itself than about the cell. The last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
from pathlib import Path
from typing import Any

from mrguide.cell.commands import CellDryRun
from mrguide.cell.dry_run import dry_run_cycles
from mrguide.cli_args import nonnegative_int, positive_int
from mrguide.config import load_section
from mrguide.deploy.cycle_report import cycle_figures, miss_anatomy
from mrguide.deploy.cycles import CycleConfig, CycleRun
from mrguide.deploy.runlog import RunLog, read_log
from mrguide.deploy.session import DeployConfig
from mrguide.experiments.sim2real import load_real_cell

WHERE = {False: "shared", True: "own"}


def twin_camera(cell: Any) -> Any:
    """The cell's twin-rendered camera pose source if its [deploy] pose_source is "camera", else None."""
    dcfg = load_section(DeployConfig, cell.path, "deploy")
    if dcfg.pose_source != "camera":
        return None
    return CellDryRun(str(cell.path)).camera(dcfg.camera, cell.path.parent, cell.env.task.object_height)


def run(
    policy: str, cell: Any, cycles: int, seed: int, own_process: bool, log: Path, bus: Any = None
) -> dict[str, Any]:
    """One run, logged to `log` (the cell's bus config, or `bus`); its figures from the log."""
    camera = twin_camera(cell)
    try:
        with RunLog(log, {"benchmark": Path(__file__).stem, "cell": WHERE[own_process]}) as run_log:
            summary = dry_run_cycles(
                policy,
                cell.env,
                bus or cell.bus,
                CycleRun(0, cycles, seed, CycleConfig()),
                run_log,
                cell.safety,
                pose_factory=camera,
                on_placed=camera.refresh if camera else None,
                own_process=own_process,
            )
    finally:
        if camera:
            camera.close()
    records = read_log(log)
    f = cycle_figures(records)
    ends = [r for r in records if r["kind"] == "cycle_end"]
    return {
        "cell": WHERE[own_process],
        "placed": summary.placed,
        "cycles": cycles,
        "missed_cycles": f["missed_cycles"],
        "work_overruns": sum(int(r["work_overruns"]) for r in ends),
        "underruns": f["underruns"],
        "steal_s": round(sum(float(r["steal_s"]) for r in ends), 2),
        "cycle_s_median": f["cycle_s_median"],
        **{k: round(v, 4) for k, v in (miss_anatomy(records) or {}).items()},
    }


def pair_parser(doc: str | None, cycles: int, pairs: int, logs: str) -> argparse.ArgumentParser:
    """The arguments of an alternating-pairs benchmark (this one, switch_interval.py); `logs` names its log files."""
    ap = argparse.ArgumentParser(description=doc, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--policy", required=True, help="exported policy file (.npz)")
    ap.add_argument("--cycles", type=positive_int, default=cycles)
    ap.add_argument("--pairs", type=positive_int, default=pairs)
    ap.add_argument("--seed", type=nonnegative_int, default=0, help="the feeder's seed")
    ap.add_argument("--cell", type=Path, default=Path(__file__).parents[1] / "configs" / "cells" / "real_cell.toml")
    ap.add_argument("--logs", type=Path, help=f"keep each run's log here ({logs})")
    return ap


def print_header(cell: Path) -> None:
    """The machine, the cell and the column heads of `print_row`."""
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; {cell.name}")
    print(f"{'cell':<7} {'placed':>9} {'missed':>7} {'overruns':>9} {'dry':>4} {'steal s':>8} {'median s':>9}")


def main() -> None:
    args = pair_parser(__doc__, 50, 2, "PAIR-shared.jsonl, PAIR-own.jsonl").parse_args()
    cell = load_real_cell(args.cell)
    print_header(args.cell)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        logs = args.logs or Path(tmp)
        logs.mkdir(parents=True, exist_ok=True)
        for pair in range(args.pairs):
            for own in (False, True):
                rows.append(run(args.policy, cell, args.cycles, args.seed, own, logs / f"{pair}-{WHERE[own]}.jsonl"))
                print_row(rows[-1])
    print(json.dumps({"policy": args.policy, "cell": args.cell.name, "cycles": args.cycles, "runs": rows}))


def print_row(r: dict[str, Any]) -> None:
    print(
        f"{r['cell']:<7} {r['placed']:>4} / {r['cycles']:<3} {r['missed_cycles']:>7} {r['work_overruns']:>9} "
        f"{r['underruns']:>4} {r['steal_s']:>8.2f} {r['cycle_s_median']:>9.2f}",
        flush=True,
    )


if __name__ == "__main__":
    main()
