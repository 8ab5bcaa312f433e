"""Where the Fig. 7 grid's final policies fail: the same 100 episodes per policy as final_policies.py, each
failure counted by its outcome and the task phase it ended in; for failures that never left the approach
(phase 0), the TCP's distance from the approach waypoint (the scripted expert's target) at the last decision —
the phase advances only within ε = 20 mm of it (Eq. 5).

    python docs/results/noise-robustness-anchor-offset/failure_phases.py > docs/results/noise-robustness-anchor-offset/failure_phases.txt
"""
import collections
import statistics
import sys
from pathlib import Path

import numpy as np

from mrguide.deploy.policy import ExportedPolicy
from mrguide.twin.env import PickPlaceEnv
from mrguide.twin.rollout import run_episodes

EPISODES = 100
FIRST_SEED = 7_000_000  # as final_policies.py


class Recorder:
    """The policy, remembering how far the TCP was from the expert's target at the last decision."""

    def __init__(self, policy: ExportedPolicy, env: PickPlaceEnv):
        self.policy, self.env = policy, env
        self.distance_mm = 0.0

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        waypoint = self.env.workspace.to_cartesian(self.env.expert_action()[:3])
        self.distance_mm = float(np.linalg.norm(obs[:3] - waypoint)) * 1000
        return self.policy(obs)


def main(sigmas: list[str]) -> None:
    here = Path(__file__).resolve().parent
    env = PickPlaceEnv()
    for sigma in sigmas:
        failures: collections.Counter = collections.Counter()
        stuck_mm: list[float] = []
        for run in sorted((here / f"sigma_{float(sigma):.3f}").glob("seed*"), key=lambda p: int(p.name[4:])):
            recorder = Recorder(ExportedPolicy.load(run / "policy.npz", env.robot_spec, env.task_cfg), env)

            def count(result, recorder=recorder):
                if result.outcome != "success":
                    failures[(result.outcome, env.phase)] += 1
                    if env.phase == 0:
                        stuck_mm.append(recorder.distance_mm)

            run_episodes(env, recorder, range(FIRST_SEED, FIRST_SEED + EPISODES), progress=count)
        total = sum(failures.values())
        print(f"sigma {float(sigma):.3f}: {total} failures in {EPISODES} episodes x 10 policies; by (outcome, final phase): "
              + ", ".join(f"{o} in phase {p}: {n}" for (o, p), n in failures.most_common()))
        if stuck_mm:
            print(f"  ended in the approach: {len(stuck_mm)}; TCP from the approach waypoint at the last decision: median "
                  f"{statistics.median(stuck_mm):.0f} mm, min {min(stuck_mm):.0f}, max {max(stuck_mm):.0f}", flush=True)
    env.close()


if __name__ == "__main__":
    main(sys.argv[1:] or ["0.02", "0.03", "0.05", "0.07"])
