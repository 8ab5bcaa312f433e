"""The twin's commands: `mrguide expert` (the scripted expert in the twin) and `mrguide calibrate --twin` (the HMD's
calibration rendered in a bare twin scene)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from mrguide.cli_args import nonnegative_int, positive_int


def add_expert_command(sub: argparse._SubParsersAction) -> None:
    sp = sub.add_parser("expert", help="run the scripted expert in the twin")
    sp.add_argument("--config", help="TOML config ([robot], [twin], [task])")
    sp.add_argument("--episodes", type=positive_int, default=50)
    sp.add_argument("--seed", type=nonnegative_int, default=0, help="first seed; episode i uses seed + i")
    sp.add_argument("--quiet", action="store_true", help="no progress bar")
    sp.set_defaults(func=cmd_expert)


def cmd_expert(args: argparse.Namespace) -> int:
    """Run the scripted expert in the twin and report success rate and timing."""
    from mrguide.twin.env import EnvConfig, PickPlaceEnv
    from mrguide.twin.rollout import run_episodes

    env = PickPlaceEnv(EnvConfig.load(args.config))
    try:
        with tqdm(total=args.episodes, desc="scripted expert", unit="ep", disable=args.quiet) as bar:

            def tick(res):
                bar.update(1)
                bar.set_postfix(last=res.outcome)

            summary = run_episodes(
                env, lambda obs: env.expert_action(), range(args.seed, args.seed + args.episodes), tick
            )
    finally:
        env.close()
    sim_s = summary.decisions * env.twin_cfg.decision_period
    print(
        f"scripted expert: {summary.success_rate:.1%} success over {len(summary.episodes)} episodes "
        f"(seeds {args.seed}..{args.seed + args.episodes - 1}); outcomes {dict(summary.outcomes())}"
    )
    print(
        f"timing: {summary.decisions} decisions in {summary.wall_s:.1f} s wall = "
        f"{summary.decisions / summary.wall_s:.0f} decisions/s, {sim_s / summary.wall_s:.1f}x real time"
    )
    return 0


def run_twin_calibration(config: Path | None, cfg: Any) -> tuple[Any, np.ndarray]:
    """`mrguide calibrate --twin`: the targets rendered by a simulated HMD in a bare twin scene, calibrated as images
    would be; returns the calibration run and the true T_base_hmd of [calibration_twin]."""
    import pybullet as pb

    from mrguide.cell_layout import TABLE_CENTER, TABLE_HALF_EXTENTS
    from mrguide.config import load_section
    from mrguide.twin.camera import look_at
    from mrguide.twin.markers import TwinCalibrationConfig, TwinHmd, calibrate_twin_hmd

    twin = load_section(TwinCalibrationConfig, config, "calibration_twin")
    client = pb.connect(pb.DIRECT)
    try:
        table = pb.createVisualShape(
            pb.GEOM_BOX, halfExtents=TABLE_HALF_EXTENTS, rgbaColor=[0.75, 0.72, 0.66, 1], physicsClientId=client
        )
        pb.createMultiBody(0, -1, table, TABLE_CENTER, physicsClientId=client)
        first = look_at(np.array(twin.views[0]), np.array(twin.look_at), np.array([0.0, 0.0, 1.0]))
        hmd = TwinHmd(client, twin.T_base_hmd, first, twin.intrinsics, twin.supersample)
        run = calibrate_twin_hmd(hmd, cfg, twin.views, twin.look_at, cfg.hmd)
    finally:
        pb.disconnect(client)
    return run, twin.T_base_hmd
