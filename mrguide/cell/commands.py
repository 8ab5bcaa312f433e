"""The dry-run backend that `mrguide deploy --dry-run` runs (the deploy command itself lives in
`mrguide.deploy.commands`): the deploy stack against a simulated cell of the config's [plant] engine."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mrguide.config import ConfigFile


class CellDryRun:
    """`deploy --dry-run` on the twin of `config` (its [twin] decision period, reality gap, camera rendering); the
    simulated cell runs in a process of its own, beside the deploy stack as a real cell's drives are."""

    def __init__(self, config: ConfigFile):
        from mrguide.cell.config import CellConfig  # imports PyBullet: only once deploy's own checks have passed

        self.env_cfg = CellConfig.from_file(config)
        self.path = config.path
        self.decision_period = self.env_cfg.twin.decision_period

    def camera(self, camera_cfg: Any, base: Path, object_height: float) -> Any:
        from mrguide.cell.camera_feed import TwinCameraPoses
        from mrguide.robot import load_robot
        from mrguide.twin.visual_arm import ArmDrawing

        return TwinCameraPoses(camera_cfg, base, object_height, ArmDrawing.of(load_robot(self.env_cfg.robot)))

    def hmd(self, seed: int) -> Any:
        from mrguide.cell.hmd_feed import HmdFeed

        return HmdFeed(self.env_cfg, self.path, seed)

    def run_cycles(self, inputs: Any, run: Any) -> Any:
        """`deploy --dry-run --cycles`: production cycles against the simulated cell, parts fed by the twin."""
        from mrguide.cell.dry_run import dry_run_cycles

        camera, learning = inputs.camera, inputs.learning
        return dry_run_cycles(
            inputs.policy_path,
            self.env_cfg,
            inputs.bus,
            run,
            inputs.run_log,
            inputs.safety,
            pose_factory=camera,
            policy=learning or inputs.policy,
            on_placed=camera.refresh if camera else None,
            runtime_cfg=inputs.dcfg.runtime,
            own_process=True,
            learning=learning,
        )

    def run(
        self,
        policy_path: str,
        policy: Any,
        bus: Any,
        episodes: int,
        seed: int,
        run_log: Any,
        safety: Any,
        runtime: Any,
        tick: Any,
        camera: Any,
    ) -> Any:
        from mrguide.cell.dry_run import dry_run

        return dry_run(
            policy_path,
            self.env_cfg,
            bus,
            episodes,
            seed,
            run_log,
            safety,
            after_episode=tick,
            policy=policy,
            runtime_cfg=runtime,
            pose_factory=camera,
            on_placed=camera.refresh if camera else None,
            own_process=True,
        )
