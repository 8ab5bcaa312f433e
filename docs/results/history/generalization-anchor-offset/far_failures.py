"""Where the Fig. 6 policies of Fig. 7's configuration fail far from the training goal region: for each seed
given, every grid goal 0.15-0.21 m from the region, 3 episodes each (start states 3,000,000-3,000,002), failures
counted by outcome and the task phase they ended in.

    python docs/results/generalization-anchor-offset/far_failures.py 0 5 7 > docs/results/generalization-anchor-offset/far_failures.txt
"""
import collections
import csv
import sys
from pathlib import Path

from mrguide.config import load_section
from mrguide.deploy.policy import ExportedPolicy
from mrguide.experiments import generalization as gen
from mrguide.experiments.runs import configs
from mrguide.twin.env import PickPlaceEnv
from mrguide.twin.rollout import run_episode

HERE = Path(__file__).resolve().parent
EPISODES = 3


def main(seeds: list[int]) -> None:
    cfg = load_section(gen.GeneralizationConfig, HERE.parents[2] / "configs/experiments/generalization_anchor_offset.toml", "experiment",
                       known=("experiment",))
    env = PickPlaceEnv(configs(gen.runs(cfg, None)[0])[3])  # the widened box the policies were trained with
    for seed in seeds:
        run = HERE / "guided" / f"seed{seed}"
        policy = ExportedPolicy.load(run / "policy.npz", env.robot_spec, env.task_cfg)
        goals = [r for r in csv.DictReader(open(run / "goals.csv")) if 0.15 <= float(r["distance_m"]) <= 0.21]
        outcomes: collections.Counter = collections.Counter()
        for g in goals:
            for k in range(EPISODES):
                result = run_episode(env, policy, 3_000_000 + k, {"goal": (float(g["x"]), float(g["y"]))})
                outcomes["success" if result.outcome == "success" else f"{result.outcome} in phase {env.phase}"] += 1
        print(f"seed {seed}: {len(goals)} goals x {EPISODES} episodes: " + ", ".join(f"{k} {v}" for k, v in outcomes.most_common()), flush=True)
    env.close()


if __name__ == "__main__":
    main([int(a) for a in sys.argv[1:]] or [0, 5, 7])
