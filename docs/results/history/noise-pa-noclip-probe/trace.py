"""One evaluation episode of a policy file, step by step: the phase, the TCP relative to the part (mm), the
policy's target relative to the scripted expert's (mm), the vacuum state and command. Shows how a policy that
is precise on the expert's states drifts once the arm strays off them.

    python docs/results/noise-pa-noclip-probe/trace.py docs/results/noise-pa-noclip-probe/sigma_0.020/seed1/policy.npz > docs/results/noise-pa-noclip-probe/trace_sigma_0.020_seed1.txt
    (and policy_target.npz > trace_sigma_0.020_seed1_target.txt)
"""
import sys

import numpy as np

from mrguide.deploy.policy import ExportedPolicy
from mrguide.twin.env import PickPlaceEnv


def main(path: str, episode: int = 0) -> None:
    env = PickPlaceEnv()
    ws = env.workspace
    policy = ExportedPolicy.load(path, env.robot_spec, env.task_cfg)
    obs, _ = env.reset(seed=5_000_000 + episode)
    print("step phase tcp-part_mm(x,y,z) target-expert_mm(x,y,z) vacuum command")
    step = 0
    while True:
        action = policy(obs)
        off = np.round((ws.to_cartesian(action[:3]) - ws.to_cartesian(env.expert_action()[:3])) * 1000).astype(int)
        rel = np.round((obs[:3] - obs[5:8]) * 1000).astype(int)
        print(f"{step} {env.phase} {rel.tolist()} {off.tolist()} {obs[3]:+.0f} {action[3]:+.2f}")
        obs, _, term, trunc, info = env.step(action)
        step += 1
        if term or trunc:
            break
    print("outcome:", info["outcome"])
    env.close()


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 0)
