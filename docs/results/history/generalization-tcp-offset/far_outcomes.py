"""Outcomes of seed 0's exported tcp_offset policy at the grid goals 0.15-0.21 m from the training region
(first 8 goals, 3 episodes each), failures printed with the phase they ended in.

    python docs/results/generalization-tcp-offset/far_outcomes.py > docs/results/generalization-tcp-offset/far_outcomes.txt
"""
import collections
import csv
from pathlib import Path

import numpy as np

from mrguide.config import load_section
from mrguide.deploy.policy import ExportedPolicy
from mrguide.experiments import generalization as gen
from mrguide.experiments.runs import configs
from mrguide.twin.env import PickPlaceEnv

HERE = Path(__file__).resolve().parent
cfg = load_section(gen.GeneralizationConfig, HERE.parents[2] / "configs/experiments/generalization_tcp_offset.toml", "experiment", known=("experiment",))
run = gen.runs(cfg, None)[0]
env = PickPlaceEnv(configs(run)[3])
policy = ExportedPolicy.load(HERE / "guided/seed0/policy.npz", env.robot_spec, env.task_cfg)
goals = [r for r in csv.DictReader(open(HERE / "guided/seed0/goals.csv")) if 0.15 <= float(r["distance_m"]) < 0.21]
outcomes = collections.Counter()
for g in goals[:8]:
    x, y = float(g["x"]), float(g["y"])
    for k in range(3):
        obs, _ = env.reset(seed=3_000_000 + k, options={"goal": (x, y)})
        while True:
            obs, _, term, trunc, info = env.step(policy(obs))
            if term or trunc:
                break
        outcomes[info["outcome"]] += 1
        if info["outcome"] != "success":
            print(f"goal ({x:.2f}, {y:.2f}) at {float(g['distance_m']):.3f} m: {info['outcome']} in phase {info['phase']}, "
                  f"object at {np.round(obs[5:8], 3)}")
env.close()
print(dict(outcomes))
