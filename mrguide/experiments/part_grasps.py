"""`mrguide grasps`: the judge's reading of a trained policy on its part, in the twin.

For each fresh episode: where the cup first held the part (the TCP in the part's frame at the first decision the
vacuum generator reported it), whether that grasp lies in the part's acceptable region clear of its keep-out windows,
and whether the part ended at its place pose (`part_judge`, the one reader of what the learner never sees; this
module is the evaluation, not the learner's path). Episodes start from env seeds 2·10⁶ + i, apart from training's
and from its evaluations'.
"""

from __future__ import annotations

import argparse
import csv
import math
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mrguide.cli_args import positive_int
from mrguide.part_judge import judge
from mrguide.parts import part_named

if TYPE_CHECKING:
    from mrguide.twin.env import EnvConfig

SEED_BASE = 2_000_000
FIELDS = ("seed", "outcome", "grasp_x", "grasp_y", "grasp_acceptable", "placed", "position_error", "yaw_error")


@dataclass(frozen=True)
class JudgedEpisode:
    """One episode of the policy, as the judge reads it (grasp in the part's frame, m; NaN where it never held it)."""

    seed: int
    outcome: str
    grasp_x: float
    grasp_y: float
    grasp_acceptable: bool
    placed: bool
    position_error: float
    yaw_error: float


def _in_part_frame(point: np.ndarray, position: np.ndarray, quaternion: np.ndarray) -> np.ndarray:
    """`point` (base frame) in the frame of a part at `position` with `quaternion` (x, y, z, w)."""
    import pybullet as pb

    rot = np.array(pb.getMatrixFromQuaternion(list(quaternion))).reshape(3, 3)
    return rot.T @ (np.asarray(point, dtype=float) - np.asarray(position, dtype=float))


def judged_episodes(policy_path: Path, env_cfg: EnvConfig, episodes: int) -> list[JudgedEpisode]:
    """Run the exported policy at `policy_path` in the twin of `env_cfg` for `episodes` fresh episodes, judged."""
    from mrguide.deploy.policy import ExportedPolicy
    from mrguide.twin.env import PickPlaceEnv

    env = PickPlaceEnv(env_cfg)
    try:
        policy = ExportedPolicy.load(policy_path, env.robot_spec, env.task_cfg)
        env.teach(policy.with_grasp(env.task_cfg))
        part = part_named(env.task_cfg.part)
        return [_episode(env, policy, part, SEED_BASE + i) for i in range(episodes)]
    finally:
        env.close()


def _episode(env, policy, part, seed: int) -> JudgedEpisode:
    obs, _ = env.reset(seed=seed)
    grasp = np.full(3, np.nan)
    while True:
        obs, _, term, trunc, info = env.step(policy(obs))
        if info["part_present"] and np.isnan(grasp[0]):
            tcp = env.decision.tcp(env.scene.joint_positions(noisy=False))
            grasp = _in_part_frame(tcp, *env.scene.object_pose())
        if term or trunc:
            break
    position, quaternion = env.scene.object_pose()
    verdict = judge(part, grasp, position, quaternion, env.scene.goal)
    held = not math.isnan(grasp[0])
    return JudgedEpisode(
        seed,
        info["outcome"],
        float(grasp[0]),
        float(grasp[1]),
        held and verdict.grasp_acceptable,
        verdict.placed,
        round(verdict.position_error, 5),
        round(verdict.yaw_error, 5),
    )


def cmd_grasps(args: argparse.Namespace) -> int:
    from mrguide.twin.env import EnvConfig

    rows = judged_episodes(Path(args.policy), EnvConfig.load(args.config), args.episodes)
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        with open(args.out, "w", newline="") as fh:
            writer = csv.DictWriter(fh, FIELDS)
            writer.writeheader()
            writer.writerows(asdict(r) for r in rows)
    n = len(rows)
    both = sum(r.grasp_acceptable and r.placed for r in rows)
    print(
        f"{n} episodes: grasp acceptable {sum(r.grasp_acceptable for r in rows)}, placed {sum(r.placed for r in rows)}, "
        f"both {both} ({both / n:.0%}); task successes {sum(r.outcome == 'success' for r in rows)}"
    )
    return 0


def add_grasps_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("grasps", help="where a trained policy grips its part and where it leaves it, as the judge sees")
    p.add_argument("--policy", required=True, help="an exported policy (policy.npz)")
    p.add_argument("--config", default=None, help="the run config it was trained with (its [task] part)")
    p.add_argument("--episodes", type=positive_int, default=50)
    p.add_argument("--out", default=None, help="write one row per episode to this CSV")
    p.set_defaults(func=cmd_grasps)
