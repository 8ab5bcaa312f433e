"""Each final exported policy of the Fig. 7 grid (the target actor, as the grid exported it) over 100
deterministic episodes from fresh start states in the training twin: its success rate with a 95 % Wilson
interval, beside the run's convergence and its last two evaluations; per σ, how many final policies succeed in
at least 80 of 100 episodes and the median success. Output in final_policies.txt.

    python docs/results/noise-robustness-anchor-offset/final_policies.py > docs/results/noise-robustness-anchor-offset/final_policies.txt
"""
import csv
import statistics
import sys
from pathlib import Path

from mrguide.deploy.policy import ExportedPolicy
from mrguide.experiments.stats import wilson
from mrguide.twin.env import PickPlaceEnv
from mrguide.twin.rollout import run_episodes

EPISODES = 100
FIRST_SEED = 7_000_000  # no training evaluation uses these start states


def main(sigmas: list[str]) -> None:
    here = Path(__file__).resolve().parent
    runs = {(r["sigma_m"], r["seed"]): r for r in csv.DictReader(open(here / "runs.csv"))}
    env = PickPlaceEnv()
    for sigma in sigmas:
        successes, converged = [], 0
        for run in sorted((here / f"sigma_{float(sigma):.3f}").glob("seed*"), key=lambda p: int(p.name[4:])):
            policy = ExportedPolicy.load(run / "policy.npz", env.robot_spec, env.task_cfg)
            counts = run_episodes(env, policy, range(FIRST_SEED, FIRST_SEED + EPISODES)).outcomes()
            lo, hi = wilson(counts["success"], EPISODES)
            rates = [row["success_rate"] for row in csv.DictReader(open(run / "eval.csv"))]
            rec = runs[(str(float(sigma)), run.name[4:])]
            others = ", ".join(f"{k} {v}" for k, v in counts.most_common() if k != "success") or "-"
            print(f"sigma {float(sigma):.3f} {run.name}: converged {'at ' + rec['convergence_step'] if rec['convergence_step'] else 'no':>9}; "
                  f"last evaluations {' '.join(rates[-2:])}; final policy {counts['success']}/{EPISODES} "
                  f"({lo:.2f}-{hi:.2f}; {others})", flush=True)
            successes.append(counts["success"])
            converged += bool(rec["convergence_step"])
        print(f"sigma {float(sigma):.3f}: {sum(s >= 80 for s in successes)} of {len(successes)} final policies succeed in >= 80 of "
              f"{EPISODES}; median {statistics.median(successes):g}; converged {converged}", flush=True)
    env.close()


if __name__ == "__main__":
    main(sys.argv[1:] or ["0", "0.01", "0.02", "0.03", "0.05", "0.07", "0.1"])
