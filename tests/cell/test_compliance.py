"""The cup's spring level-compensator ([twin.cup]): a press into the part is absorbed, a push beyond the stroke
still quick-stops (the dry run: runtime, CANopen, simulated drives, the twin as the plant)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mrguide.config import load_section
from mrguide.robot import RobotConfig, Workspace, load_robot
from mrguide.twin.config import TwinConfig
from mrguide.twin.env import EnvConfig
from tests.deploy.test_safety import events

REAL_CELL = Path(__file__).resolve().parents[2] / "configs" / "cells" / "real_cell.toml"
STROKE = 0.012  # the shipped real cell's level-compensator


def _cell(floor: float | None = None) -> EnvConfig:
    twin = load_section(TwinConfig, REAL_CELL, "twin")
    assert twin.cup.stroke == STROKE
    robot = RobotConfig()
    if floor is not None:  # lower the workspace box so a target may lie deeper than the stroke
        box = load_robot().workspace
        robot = RobotConfig(workspace=Workspace(low=(box.low[0], box.low[1], floor), high=tuple(box.high)))
    return EnvConfig(robot=robot, twin=twin)


def _press(depth: float, compressions: list[float]):
    """A grasp phase that drives the cup `depth` m into the part's top, vacuum off (no seal to stop it)."""
    to_normalized = load_robot().workspace.to_normalized

    def hook(obs, phase, a, cell):
        with cell.plant.lock:
            compressions.append(cell.scene.cup_compression())
        if phase != 1:
            return a
        target = np.asarray(obs[5:8], float) + np.array([0.0, 0.0, 0.025 - depth])
        return np.concatenate([to_normalized(target), [-1.0]]).astype(np.float32)

    return hook


def test_a_press_within_the_stroke_is_absorbed_not_a_fault(run_dry):
    """5 mm into the part (the workspace floor): without the compensator some such episodes end in a drive's
    following-error EMCY (`docs/results/compliance/press_probe.csv`); with it the cup retracts and no safety event
    occurs but the clamps of the workspace box and of the descent rule (the hook's target slides the pressed cup)."""
    compressions: list[float] = []
    summary, log, _ = run_dry(episodes=3, env_cfg=_cell(), hook=_press(0.005, compressions))
    assert [e.outcome for e in summary.episodes] == ["no_grasp"] * 3 and summary.stopped is None
    assert [e for e in events(log) if e[0] not in ("workspace", "descent")] == []
    assert 0.003 < max(compressions) < STROKE  # the spring took the press


def test_a_push_beyond_the_stroke_still_quick_stops(run_dry):
    """25 mm into the part with a 12 mm stroke: the compensator bottoms out and the arm pushes rigidly, as into an
    obstacle; the drives' following-error monitoring stops it."""
    compressions: list[float] = []
    summary, log, _ = run_dry(episodes=1, env_cfg=_cell(floor=0.02), hook=_press(0.025, compressions))
    assert summary.stopped is not None and summary.episodes[0].outcome == "safety_stop"
    assert events(log)[-1][1] == "quick_stop" and events(log)[-1][0] in ("drive_fault", "following_error")
    assert max(compressions) > STROKE - 0.001
