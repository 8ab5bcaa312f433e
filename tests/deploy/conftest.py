"""Shared pieces for the deploy tests: the scripted expert as a policy and a dry-run helper."""

import itertools

import numpy as np
import pytest

from mrguide.deploy.runlog import RunLog
from mrguide.drivers.config import BusConfig, CobotBusConfig
from mrguide.robot import load_robot
from mrguide.task import oracle_action, phase_from_progress
from mrguide.twin.dry_run import dry_run
from mrguide.twin.env import EnvConfig

_channels = itertools.count()


def bus_config() -> CobotBusConfig:
    """Default bus description on a virtual channel of its own (tests never share a bus)."""
    return CobotBusConfig(bus=BusConfig(interface="virtual", channel=f"deploy-test-{next(_channels)}"))


class Expert:
    """The scripted expert as a deploy policy; `hook(obs, phase)` may inject faults or misbehave."""

    def __init__(self, cfg: EnvConfig, hook=None):
        self.cfg, self.hook = cfg, hook
        self.ws = load_robot(cfg.robot).workspace

    def __call__(self, obs):
        a = oracle_action(obs, self.cfg.task, self.ws.to_normalized)
        if self.hook:
            a = self.hook(obs, phase_from_progress(obs[4]), a)
        return np.asarray(a, dtype=np.float32)


@pytest.fixture()
def run_dry(tmp_path):
    """dry_run with the expert; returns (summary, run log path, the cell the run used).

    `pose(cell)` may give the object pose source (default: the exact pose from the twin); `runtime_cfg`
    sets the runtime (RuntimeConfig)."""

    def run(episodes=1, seed=0, hook=None, env_cfg=None, safety=None, on_cell=None, max_recoveries=0, pose=None,
            runtime_cfg=None):
        cfg = env_cfg or EnvConfig()
        cells = []

        def pose_factory(cell):
            from mrguide.twin.plant import TwinObjectPose

            cells.append(cell)
            if on_cell:
                on_cell(cell)
            return pose(cell) if pose else TwinObjectPose(cell.plant)

        log = tmp_path / f"run-{seed}.jsonl"
        with RunLog(log, {"test": "dry run"}) as run_log:
            summary = dry_run(None, cfg, bus_config(), episodes, seed, run_log, safety,
                              pose_factory=pose_factory,
                              policy=Expert(cfg, (lambda o, p, a: hook(o, p, a, cells[0])) if hook else None),
                              max_recoveries=max_recoveries, runtime_cfg=runtime_cfg)
        return summary, log, cells[0]

    return run
