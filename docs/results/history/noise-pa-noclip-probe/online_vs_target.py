"""The final online actor (policy.npz) against the final target actor (policy_target.npz, the Polyak average of
the actor's weights, exported from the run's checkpoint after training) of each run here: 30 deterministic
episodes each in the training twin, outcomes counted. Output in online_vs_target.txt.

    python docs/results/noise-pa-noclip-probe/online_vs_target.py > docs/results/noise-pa-noclip-probe/online_vs_target.txt
"""
from pathlib import Path

from mrguide.deploy.policy import ExportedPolicy
from mrguide.twin.env import PickPlaceEnv
from mrguide.twin.rollout import run_episodes

EPISODES = 30


def outcomes(policy: ExportedPolicy, env: PickPlaceEnv) -> str:
    counts = run_episodes(env, policy, range(5_000_000, 5_000_000 + EPISODES)).outcomes()
    return f"success {counts['success']}/{EPISODES} ({', '.join(f'{k} {v}' for k, v in counts.most_common() if k != 'success') or '-'})"


def main() -> None:
    here = Path(__file__).resolve().parent
    env = PickPlaceEnv()
    for run in sorted(here.glob("sigma_*/seed*")):
        online, target = (ExportedPolicy.load(run / name, env.robot_spec, env.task_cfg) for name in ("policy.npz", "policy_target.npz"))
        print(f"{run.parent.name}/{run.name}: online actor {outcomes(online, env)}; target actor {outcomes(target, env)}", flush=True)
    env.close()


if __name__ == "__main__":
    main()
