"""Where the 'real' cell's cup lets go: every break of the suction constraint in dry-run episodes of a policy, with
and without the runtime's break-away rule (docs/robot.md, the lift rules).

Each variant runs `--seeds` × `--episodes` episodes of the policy through the whole stack against the cell of
`--cell` (exact poses; a safety stop is fault-reset and the next episode runs). Every break is written to
OUT/breaks.csv with the phase the episode was in, the load on the cup (N, m (a − g) of the hanging part in its frame;
z < 0 pulls the part, z > 0 presses it) and the cup's position in the part's frame (m; the top face is at z = half
the part's height); the outcomes to OUT/break_outcomes.csv. Prints one line per variant.

    python tools/break_probe.py --policy P [--seeds 3] [--episodes 20] [--out docs/results/compliance]
"""

from __future__ import annotations

import argparse
import csv
import tempfile
from collections import Counter
from pathlib import Path

import numpy as np

from mrguide.cell.dry_run import dry_run
from mrguide.cell.twin_plant import TwinObjectPose
from mrguide.deploy.policy import ExportedPolicy
from mrguide.deploy.runlog import RunLog
from mrguide.deploy.runtime_config import RuntimeConfig
from mrguide.experiments.sim2real import load_real_cell
from mrguide.robot import load_robot
from mrguide.task import OBS_PROGRESS, phase_from_progress

#: variant -> the runtime it runs with
VARIANTS = {"break-away (default)": RuntimeConfig(), "no break-away": RuntimeConfig(break_away_distance=0.0)}


class Recorder:
    """The policy, wrapped to know the phase; the cup's breaks, recorded with it."""

    def __init__(self, policy: ExportedPolicy, variant: str, seed: int):
        self.policy, self.variant, self.seed = policy, variant, seed
        self.episode, self.phase = 0, 0
        self.breaks: list[dict] = []
        self.outcomes: list[dict] = []

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        self.phase = phase_from_progress(float(obs[OBS_PROGRESS]))
        return self.policy(obs)

    def pose_factory(self, cell) -> TwinObjectPose:
        cell.scene.suction.on_break = self.on_break
        return TwinObjectPose(cell.plant)

    def on_break(self, force: tuple[float, ...], cup: tuple[float, ...]) -> None:
        self.breaks.append(
            {"variant": self.variant, "seed": self.seed, "episode": self.episode, "phase": self.phase}
            | {f"f{a}": round(v, 2) for a, v in zip("xyz", force, strict=True)}
            | {f"cup_{a}": round(v, 4) for a, v in zip("xyz", cup, strict=True)}
        )

    def after_episode(self, report) -> None:
        self.outcomes.append(
            {"variant": self.variant, "seed": self.seed, "episode": self.episode, "outcome": report.outcome.value}
        )
        self.episode += 1


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--policy", required=True, help="exported policy file (.npz)")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--episodes", type=int, default=20, help="per seed")
    ap.add_argument("--cell", default="configs/cells/real_cell.toml")
    ap.add_argument("--out", default="docs/results/compliance", help="directory for breaks.csv, break_outcomes.csv")
    args = ap.parse_args(argv)
    cell = load_real_cell(args.cell)
    policy = ExportedPolicy.load(args.policy, load_robot(cell.env.robot), cell.env.task)
    breaks: list[dict] = []
    outcomes: list[dict] = []
    with tempfile.TemporaryDirectory() as scratch:
        for variant, runtime_cfg in VARIANTS.items():
            for seed in range(args.seeds):
                rec = Recorder(policy, variant, seed)
                with RunLog(Path(scratch) / f"{len(outcomes)}.jsonl", {"probe": "breaks"}) as log:
                    dry_run(
                        None, cell.env, cell.bus, args.episodes, seed, log, cell.safety, rec.pose_factory,
                        rec.after_episode, policy=rec, max_recoveries=args.episodes, runtime_cfg=runtime_cfg,
                    )  # fmt: skip
                breaks += rec.breaks
                outcomes += rec.outcomes
            ended = Counter(o["outcome"] for o in outcomes if o["variant"] == variant)
            pulls = [b for b in breaks if b["variant"] == variant and b["fz"] < 0]
            print(
                f"{variant}: {sum(ended.values())} episodes, outcomes {dict(ended)}; "
                f"{len(pulls)} breaks pulling the part, in phases {dict(Counter(b['phase'] for b in pulls))}"
            )
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name, rows in (("breaks.csv", breaks), ("break_outcomes.csv", outcomes)):
        with (out / name).open("w", newline="") as fh:
            fields = list(rows[0]) if rows else ["variant"]
            writer = csv.DictWriter(fh, fieldnames=fields)
            writer.writeheader()
            writer.writerows(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
