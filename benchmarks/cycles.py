"""Production-cycle benchmark: cycle time and parts per hour of a policy beside the scripted expert's.

Run: python benchmarks/cycles.py --policy docs/results/sim2real-main5k/policy.npz [--cycles N] [--cell ...]. Both
run `--cycles` production cycles (`mrguide deploy --cycles`) through the whole stack against the simulated cell
of --cell (default: the 'real' twin of configs/cells/real_cell.toml), one after the other, with the same feeder
seed: the same parts at the same poses, the same goals. The scripted expert through the same stack is the
reference "hand-written program". Prints a table; the last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
from pathlib import Path

from mrguide.cell.dry_run import dry_run_cycles
from mrguide.cli_args import nonnegative_int, positive_int
from mrguide.deploy.cycles import CycleConfig, CycleRun, CycleSummary
from mrguide.deploy.runlog import RunLog
from mrguide.experiments.sim2real import load_real_cell
from mrguide.robot import load_robot
from mrguide.task import oracle_action


def run(policy_path: str | None, cell, cycles: int, seed: int) -> CycleSummary:
    """`cycles` production cycles of the policy file, or (None) of the scripted expert, in `cell`."""
    ws = load_robot(cell.env.robot).workspace
    policy = None if policy_path else lambda obs: oracle_action(obs, cell.env.task, ws.to_normalized)
    with tempfile.TemporaryDirectory() as tmp, RunLog(Path(tmp) / "log.jsonl", {"benchmark": "cycles"}) as run_log:
        return dry_run_cycles(
            policy_path,
            cell.env,
            cell.bus,
            CycleRun(0, cycles, seed, CycleConfig()),
            run_log,
            cell.safety,
            policy=policy,
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--policy", required=True, help="exported policy file (.npz)")
    ap.add_argument("--cycles", type=positive_int, default=50)
    ap.add_argument("--seed", type=nonnegative_int, default=0, help="the feeder's seed")
    ap.add_argument("--cell", type=Path, default=Path(__file__).parents[1] / "configs" / "cells" / "real_cell.toml")
    args = ap.parse_args()
    cell = load_real_cell(args.cell)
    rows = {"policy": run(args.policy, cell, args.cycles, args.seed), "expert": run(None, cell, args.cycles, args.seed)}
    res = {}
    for name, s in rows.items():
        d = s.as_dict()
        res[name] = {
            k: d[k] for k in ("cycles", "placed", "retries", "cycle_s_median", "cycle_s_p95", "parts_per_hour")
        }
        res[name]["alarms"] = len(d["alarms"])
        res[name]["missed_cycles"], res[name]["underruns"] = d["missed_cycles"], d["underruns"]
    res["cycle_time_ratio"] = res["policy"]["cycle_s_median"] / res["expert"]["cycle_s_median"]
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; cell {args.cell.name}"
    )
    print(f"{'':<8} {'placed':>10} {'retries':>8} {'alarms':>6} {'median s':>9} {'p95 s':>7} {'parts/h':>8}")
    for name in rows:
        r = res[name]
        print(
            f"{name:<8} {r['placed']:>4} / {r['cycles']:<4} {sum(r['retries'].values()):>8} {r['alarms']:>6} "
            f"{r['cycle_s_median']:>9.2f} {r['cycle_s_p95']:>7.2f} {r['parts_per_hour']:>8.0f}"
        )
    print(f"policy cycle time / scripted expert's (median): {res['cycle_time_ratio']:.2f} (target <= 1.1)")
    print(json.dumps(res))


if __name__ == "__main__":
    main()
