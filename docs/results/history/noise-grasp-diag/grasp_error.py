"""How far the trained actor's grasp target lies from the part (Fig. 7 diagnosis).

For each run directory given (a training run with a policy.npz), plays 30 evaluation episodes in the
training twin and prints the outcomes and, over every decision taken in the grasp phase, the distance
(x/y, per axis) of the actor's target from the oracle's (the part's top centre) and the height of the
actor's target above the oracle's (z; positive: the cup is sent to stop above the part). The cup seals only
when it lands within about 13 mm of the centre per axis.

    python docs/results/noise-grasp-diag/grasp_error.py docs/results/noise-grasp-diag/sigma_*/seed* 2>/dev/null > docs/results/noise-grasp-diag/grasp_error.txt

The policies are the final ones of seeds 0-2 of the runs in docs/results/noise-robustness (stored reading,
20k steps; their eval.csv are the committed ones). Retrained on 2026-11-30, seed 0 at 0, 0.02 and 0.05 m gave
the same weights and eval.csv.
"""
import collections
import sys
from pathlib import Path

import numpy as np

from mrguide.deploy.policy import ExportedPolicy
from mrguide.twin.env import PickPlaceEnv

EPISODES = 30


def diagnose(run: Path) -> str:
    env = PickPlaceEnv()
    policy = ExportedPolicy.load(run / "policy.npz", env.robot_spec, env.task_cfg)
    ws = env.workspace
    outcomes: collections.Counter = collections.Counter()
    errors = []
    for k in range(EPISODES):
        obs, _ = env.reset(seed=5_000_000 + k)
        while True:
            action = policy(obs)
            if env.phase == 1:
                errors.append(ws.to_cartesian(action[:3]) - ws.to_cartesian(env.expert_action()[:3]))
            obs, _, term, trunc, info = env.step(action)
            if term or trunc:
                break
        outcomes[info["outcome"]] += 1
    env.close()
    errors_mm = np.array(errors) * 1000
    err, dz = np.abs(errors_mm[:, :2]), errors_mm[:, 2]  # mm per axis (x, y); z signed
    worst = err.max(axis=1)
    return (f"{run}: {dict(outcomes)}; grasp-phase decisions {len(err)}, |error| per axis median "
            f"{np.median(err):.1f} mm, p90 {np.percentile(err, 90):.1f} mm; both axes within 13 mm: "
            f"{np.mean(worst < 13):.0%}; z above the oracle's median {np.median(dz):.1f} mm")


if __name__ == "__main__":
    for arg in sys.argv[1:]:
        print(diagnose(Path(arg)))
