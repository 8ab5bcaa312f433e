"""The failing episode of trace_sigma_0.050_seed0_start7000003.txt again, with the run's final critic: at each
decision the target actor's target (the exported policy, which plays), the online actor's, the scripted
expert's, and the first critic's Q of each. Shows whether the critic separates the actor's jump to the box's
corner from the expert's waypoint. Weights: sigma_0.050/seed0_networks.pt (critic, actor, target actor of the
final checkpoint; `--extract RUN/checkpoint.pt` writes it from a re-run of that grid run, checkpoints are not
committed).

    python docs/results/noise-robustness-anchor-offset/q_along_trace.py > docs/results/noise-robustness-anchor-offset/q_along_trace.txt
"""
import sys
from pathlib import Path

import numpy as np
import torch

from mrguide.policies.checkpoint import read_checkpoint
from mrguide.policies.ddpg import DDPG, DDPGConfig, obs_scaling
from mrguide.twin.env import PickPlaceEnv

HERE = Path(__file__).resolve().parent
NETWORKS = HERE / "sigma_0.050" / "seed0_networks.pt"
START = 7_000_003
NETS = ("critic", "actor", "actor_target")


def main() -> None:
    env = PickPlaceEnv()
    ws = env.workspace
    agent = DDPG(*obs_scaling(ws), 4, DDPGConfig(actor_head="anchor_offset", act_with_target=True))
    for name, state in torch.load(NETWORKS).items():
        getattr(agent, name).load_state_dict(state)
    print("step phase tcp-part_mm target_actor_mm online_actor_mm expert_mm Q(target) Q(online) Q(expert)")
    obs, _ = env.reset(seed=START)
    for step in range(env.task_cfg.horizon):
        o = torch.as_tensor(obs[None], dtype=torch.float32)
        with torch.no_grad():
            acts = [agent.actor_target(o), agent.actor(o), torch.as_tensor(env.expert_action()[None], dtype=torch.float32)]
            qs = [float(agent.critic(o, a, slice(0, 1))) for a in acts]
        rel = np.round((obs[:3] - obs[5:8]) * 1000).astype(int).tolist()
        targets = [np.round(ws.to_cartesian(a[0, :3].numpy()) * 1000).astype(int).tolist() for a in acts]
        print(step, env.phase, rel, *targets, *(f"{q:.1f}" for q in qs))
        obs, _, term, trunc, _ = env.step(acts[0][0].numpy())
        if term or trunc:
            break
    env.close()


def extract(checkpoint: str) -> None:
    state = read_checkpoint(Path(checkpoint))["agent"]
    torch.save({name: state[name] for name in NETS}, NETWORKS)


if __name__ == "__main__":
    extract(sys.argv[2]) if sys.argv[1:2] == ["--extract"] else main()
