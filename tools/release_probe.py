"""Where a policy opens the vacuum over the goal: for each policy file, episodes in the training twin (exact poses)
and, over those that released the part (success or misplaced), how far the TCP opened from the goal's top and where
the part came to rest; where it grasped, and how often it never completed the approach. The success rule asks the
TCP to open within ε (2 cm) of the goal's top and the part to lie within `place_tolerance` (3 cm) of the goal; a
policy whose openings sit near ε fails at the slightest drift.

Prints one line per policy and writes OUT/release_probe.csv:

    python tools/release_probe.py POLICY... [--episodes 15] [--out DIR]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mrguide.cli_args import positive_int
from mrguide.deploy.policy import ExportedPolicy
from mrguide.experiments import report
from mrguide.task import OBS_GOAL, Phase
from mrguide.twin.env import PickPlaceEnv

#: Start states of the probe: seeds from here on (none an evaluation of a training run uses first).
FIRST_SEED = 1000
FIELDS = [
    "policy",
    "episodes",
    "success",
    "released",
    "tcp_goal_median_m",
    "part_goal_median_m",
    "grasp_offset_m",
    "never_approached",
]


def probe(env: PickPlaceEnv, policy: ExportedPolicy, episodes: int) -> dict[str, float | int]:
    """Roll `policy` out for `episodes` episodes; the release and grasp figures of those that got that far, and how
    many never completed the approach (the TCP never within ε of the pre-grasp point)."""
    outcomes, tcp_goal, part_goal, grasp, stuck = [], [], [], [], 0
    for i in range(episodes):
        obs, _ = env.reset(seed=FIRST_SEED + i)
        goal, phase = obs[OBS_GOAL].astype(float), Phase.APPROACH
        while True:
            obs, _, term, trunc, info = env.step(policy(obs))
            tcp = env.decision.tcp(env.scene.joint_positions())
            part = env.scene.object_position()
            if phase == Phase.GRASP and info["phase"] == Phase.LIFT:
                grasp.append(float(np.linalg.norm((tcp - part)[:2])))
            phase = info["phase"]
            if term or trunc:
                break
        outcomes.append(info["outcome"])
        stuck += int(phase == Phase.APPROACH)
        if info["outcome"] in ("success", "misplaced"):
            tcp_goal.append(float(np.linalg.norm(tcp[:2] - goal[:2])))
            part_goal.append(float(np.linalg.norm(part[:2] - goal[:2])))
    return {
        "episodes": episodes,
        "success": outcomes.count("success"),
        "released": len(tcp_goal),
        "tcp_goal_median_m": _median(tcp_goal),
        "part_goal_median_m": _median(part_goal),
        "grasp_offset_m": _median(grasp),
        "never_approached": stuck,
    }


def _median(values: list[float]) -> float:
    return round(float(np.median(values)), 4) if values else float("nan")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python tools/release_probe.py", description=__doc__.split("\n")[0])
    p.add_argument("policies", nargs="+", help="exported policy files (policy.npz)")
    p.add_argument("--episodes", type=positive_int, default=15)
    p.add_argument("--out", default=None, help="directory for release_probe.csv (default: print only)")
    args = p.parse_args(argv)
    env = PickPlaceEnv()
    rows = []
    for path in args.policies:
        row = {"policy": path, **probe(env, ExportedPolicy.load(path), args.episodes)}
        rows.append(row)
        print(", ".join(f"{k} {v}" for k, v in row.items()), flush=True)
    env.close()
    if args.out:
        report.write_report(Path(args.out), {"release_probe.csv": report.csv_bytes(rows, FIELDS)})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
