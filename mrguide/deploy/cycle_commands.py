"""`mrguide deploy --cycles N`: production cycles on the robot (parts found by the camera or placed by the operator)
or in the dry-run cell (a simulated feeder), `--resume` going on from a run log's count."""

from __future__ import annotations

import argparse
import dataclasses
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from mrguide.deploy.cycles import CycleReport, CycleRun, CycleSummary
from mrguide.deploy.interrupt import finish_cycle_on_interrupt
from mrguide.deploy.runlog import RunLogError, read_log
from mrguide.pose_source import PoseUnavailable

if TYPE_CHECKING:
    from mrguide.deploy.deploy_inputs import DeployInputs
    from mrguide.deploy.session import DeployConfig

#: How long the robot's feeder waits for the camera to see the next part in the pick region (s).
PART_WAIT_S = 30.0


def cycles_done(log_path: Path) -> tuple[int, int]:
    """Where a run log's production run goes on: its next cycle (one past the last it finished) and the episode
    index of its next attempt ((0, 0) for a log without cycles). RunLogError if the log cannot be read."""
    if not log_path.exists():
        raise RunLogError(f"--resume {log_path}: no such run log")
    records = read_log(log_path)
    cycles = [r["cycle"] for r in records if r.get("kind") == "cycle_end" and isinstance(r.get("cycle"), int)]
    episodes = [r["episode"] for r in records if r.get("kind") == "episode_end" and isinstance(r.get("episode"), int)]
    return (max(cycles) + 1 if cycles else 0), (max(episodes) + 1 if episodes else 0)


class RobotFeeder:
    """On the robot: the camera finds the next part in the pick region, or the operator puts it on the fixture."""

    def __init__(self, camera: Any, dcfg: DeployConfig):
        self.camera, self.dcfg = camera, dcfg
        self.tracks_part = camera is not None  # a fixed fixture pose does not see where a lost part went

    def next_part(self, cycle: int) -> None:
        if self.camera is None:
            input(f"cycle {cycle}: place the part at {self.dcfg.object_position} and press Enter ")
            return
        (x0, y0), (x1, y1) = self.dcfg.cycles.pick_region
        end = time.monotonic() + PART_WAIT_S
        while time.monotonic() < end:
            pose = self.camera.wait_for_pose(after=time.monotonic(), timeout=PART_WAIT_S)
            x, y = np.asarray(pose.position, dtype=float)[:2]
            if x0 <= x <= x1 and y0 <= y <= y1:
                return
        raise PoseUnavailable(f"no part seen in the pick region within {PART_WAIT_S:g} s")

    def clear_part(self, cycle: int) -> None:
        input(f"cycle {cycle}: remove the part the alarm left behind and press Enter ")


def cycle_run(
    args: argparse.Namespace, dcfg: DeployConfig, seed: int, start: tuple[int, int], bar: Any, learning: Any = None
) -> CycleRun:
    """What `--cycles` asks for, from `start` (cycle, attempt); the progress bar ticks once per cycle (with
    `learning`, the on-cell learner's actor, it names the policy version acted with and the interventions played, and
    the annotation page's status follows)."""

    def tick(report: CycleReport) -> None:
        bar.update(1)
        learned = {}
        if learning is not None:
            learning.cycle_done(report.cycle, report.placed)
            learned = {"policy": f"v{learning.versions.version}", "interventions": learning.counts.played}
        bar.set_postfix(placed=report.placed, attempts=len(report.outcomes), s=f"{report.cycle_s:.1f}", **learned)

    return CycleRun(start[0], args.cycles - start[0], seed, dcfg.cycles, tick, first_attempt=start[1])


def run_cycles(run: CycleRun, dry: Any, inputs: DeployInputs) -> CycleSummary:
    """The cycles on the dry-run backend `dry` or (None) on the robot, Ctrl-C finishing the cycle in progress."""
    with finish_cycle_on_interrupt() as interrupt:
        run = dataclasses.replace(run, interrupt=interrupt)
        if dry is not None:
            return dry.run_cycles(inputs, run)
        return _robot_cycles(run, inputs)


def _robot_cycles(run: CycleRun, inputs: DeployInputs) -> CycleSummary:
    from mrguide.deploy.cycles import CycleRunner
    from mrguide.deploy.runtime import Runtime
    from mrguide.deploy.session import FixedObjectPose
    from mrguide.drivers.cobot import Cobot
    from mrguide.drivers.realtime import settled_heap

    i = inputs
    goals = i.dcfg.goals
    with settled_heap(), Cobot(i.bus, i.spec) as cobot:
        cobot.enable()
        pose = i.camera or FixedObjectPose(i.dcfg.object_position)
        policy = i.learning or i.policy
        with Runtime(
            cobot, policy, pose, i.spec, i.task, i.run_log, i.policy.decision_period, i.dcfg.runtime, i.safety
        ) as rt:
            rt.learning = i.learning
            feeder = RobotFeeder(i.camera, i.dcfg)
            runner = CycleRunner(rt, feeder, lambda c: np.array(goals[c % len(goals)]), run.config, run.after_cycle)
            return runner.run(run.start, run.count, run.interrupt, run.first_attempt)
