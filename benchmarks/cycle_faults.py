"""Faults injected mid-run into production cycles: what each does, and that nothing out of limits is ever sent.

Run: python benchmarks/cycle_faults.py [--cycles 5] [--out runs/cycle_faults]. For each fault, `--cycles`
production cycles of the scripted expert run through the whole stack against the 'real' cell
(configs/cells/real_cell.toml, exact poses), and the fault is injected in cycle 2:

- drive_emcy: node 4 faults (EMCY) during the transport;
- frame_loss: 30 % of all CAN frames, both directions, are dropped for 2 s from the lift on;
- vacuum_leak: the vacuum line leaks (no vacuum holds) from the lift on, until the next approach;
- camera_gone: the pose source has no pose for 5 s from the first decision of the cycle on.

Each run's log is kept in --out; the table says how the run ended, what the cycles did, and how many logged
setpoints lie outside the arm's position or velocity limits (must be 0). The last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

from mrguide.cell.dry_run import dry_run_cycles
from mrguide.cell.twin_plant import TwinObjectPose
from mrguide.cli_args import positive_int
from mrguide.deploy.cycle_report import cycle_figures
from mrguide.deploy.cycles import CycleConfig, CycleRun
from mrguide.deploy.runlog import RunLog, read_log
from mrguide.experiments.sim2real import load_real_cell
from mrguide.pose_source import PoseUnavailable
from mrguide.robot import load_robot
from mrguide.task import OBS_PROGRESS, Phase, oracle_action, phase_from_progress

FAULT_CYCLE = 2
FAULTS = ("drive_emcy", "frame_loss", "vacuum_leak", "camera_gone")


class Injector:
    """The scripted expert as the policy, injecting `fault` at its moment in cycle FAULT_CYCLE."""

    def __init__(self, fault: str, cell_env):
        self.fault, self.env = fault, cell_env
        self.ws = load_robot(cell_env.robot).workspace
        self.cell: Any = None  # the SimulatedCell, once the pose source is made
        self.current_cycle = 0  # the cycle in progress
        self.done = False
        self.blind_until = 0.0

    def pose_factory(self, cell):
        self.cell = cell
        outer = self

        class Source(TwinObjectPose):
            def object_position(self) -> np.ndarray:
                if time.monotonic() < outer.blind_until:
                    raise PoseUnavailable("camera gone (injected)")
                return super().object_position()

        return Source(cell.plant)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        phase = phase_from_progress(float(obs[OBS_PROGRESS]))
        self._inject(phase)
        return oracle_action(obs, self.env.task, self.ws.to_normalized)

    def _inject(self, phase: int) -> None:
        sim = self.cell.sim
        if self.fault == "vacuum_leak" and self.done and phase == Phase.APPROACH:
            sim.set_vacuum_leak(0.0)
        if self.done or self.current_cycle != FAULT_CYCLE:
            return
        if self.fault == "drive_emcy" and phase == Phase.TRANSPORT:
            sim.inject_drive_fault(4)
        elif self.fault == "frame_loss" and phase == Phase.LIFT:
            sim.faults.set_drop_rate(0.3)
            threading.Timer(2.0, sim.faults.set_drop_rate, args=(0.0,)).start()
        elif self.fault == "vacuum_leak" and phase == Phase.LIFT:
            sim.set_vacuum_leak(1.0)
        elif self.fault == "camera_gone":
            self.blind_until = time.monotonic() + 5.0
        else:
            return
        self.done = True

    def cycle_ended(self, report) -> None:
        self.current_cycle = report.cycle + 1


def out_of_limits(records: list[dict], spec) -> int:
    """Logged setpoints outside the position limits, or whose step from the one before exceeds v_max."""
    bad = 0
    for r in records:
        if r.get("kind") != "decision" or "setpoints" not in r:
            continue
        q = np.array(r["setpoints"])
        bad += int(np.sum(np.any((q < spec.q_lower - 1e-6) | (q > spec.q_upper + 1e-6), axis=1)))
        dq = np.abs(np.diff(q, axis=0)) / 0.004
        bad += int(np.sum(np.any(dq > spec.v_max * (1 + 1e-4) + 1e-4, axis=1)))
    return bad


def run_fault(fault: str, cycles: int, out: Path) -> dict:
    cell = load_real_cell(Path(__file__).parents[1] / "configs" / "cells" / "real_cell.toml")
    inj = Injector(fault, cell.env)
    log = out / f"{fault}.jsonl"
    log.unlink(missing_ok=True)
    with RunLog(log, {"command": "deploy", "benchmark": "cycle_faults", "fault": fault}) as run_log:
        summary = dry_run_cycles(
            None,
            cell.env,
            cell.bus,
            CycleRun(0, cycles, 0, CycleConfig(), after_cycle=inj.cycle_ended),
            run_log,
            cell.safety,
            pose_factory=inj.pose_factory,
            policy=inj,
        )
    records = read_log(log)
    figures = cycle_figures(records)
    return {
        "fault": fault,
        "injected": inj.done,
        "cycles": figures["cycles"],
        "placed": figures["placed"],
        "retries": figures["retries"],
        "alarms": figures["alarms"],
        "stopped": summary.stopped,
        "out_of_limit_setpoints": out_of_limits(records, load_robot(cell.env.robot)),
        "log_complete": records[-1].get("kind") == "cycles_end",
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--cycles", type=positive_int, default=5)
    ap.add_argument("--out", type=Path, default=Path("runs/cycle_faults"))
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    rows = [run_fault(f, args.cycles, args.out) for f in FAULTS]
    print(f"{'fault':<12} {'placed':>8} {'retries':<18} {'alarms':>6} {'bad sp':>6}  how the run ended")
    for r in rows:
        retries = ", ".join(f"{k} {v}" for k, v in r["retries"].items()) or "none"
        print(
            f"{r['fault']:<12} {r['placed']:>3} / {r['cycles']:<2} {retries:<18} {r['alarms']:>6} "
            f"{r['out_of_limit_setpoints']:>6}  {r['stopped'] or 'all cycles run'}"
        )
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
