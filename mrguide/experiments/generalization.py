"""Generalization (paper Fig. 6): success as a function of the goal's distance from the training goal region.

The guided seeds are trained as usual (goals drawn from the training region) but with a workspace box
wide enough to reach goals up to `max_distance` from that region. Each trained policy (its exported
`policy.npz`, run by the same numpy runner as on the robot) is then evaluated on a grid of goal targets
around the region, `episodes` per target, object starts drawn from the object region. Targets are binned
by their nearest distance to the training region; each bin reports its success with a 95 % Wilson CI.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from mrguide.config import ConfigError, Range, check_ranges
from mrguide.experiments import report
from mrguide.experiments.registry import Experiment, register
from mrguide.experiments.stats import wilson
from mrguide.experiments.train_runs import TrainRun, run_config

#: The paper's Fig. 6 in words: above 90 % near the training region, below 20 % at the largest offset (0.18 m).
PAPER_NEAR, PAPER_FAR, PAPER_FAR_AT = 0.90, 0.20, 0.18
EVAL_SEED_BASE = 2_000_000  # evaluation episode seeds (disjoint from training and the training evaluations)


@dataclass(frozen=True)
class GeneralizationConfig:
    """[experiment] of configs/experiments/generalization.toml."""

    seeds: Annotated[int, Range(1, 1000)] = 10
    steps: Annotated[int, Range(1, 10**8)] = 20_000
    workspace_low: tuple[float, float, float] = (0.16, -0.20, 0.045)  # wide enough for goals 0.21 m from the region
    workspace_high: tuple[float, float, float] = (0.72, 0.54, 0.35)
    #: m between goal targets (119 targets: 20 episodes each per seed ≈ 1 h of one core)
    grid_step: Annotated[float, Range(0.005, 0.5, " m")] = 0.05
    #: m from the training goal region (the target: at least 0.21)
    max_distance: Annotated[float, Range(0.0, 1.0, " m")] = 0.21
    bin_width: Annotated[float, Range(0.005, 1.0, " m")] = 0.03
    episodes: Annotated[int, Range(1, 10_000)] = 20  # per target and seed
    config: str = ""
    overrides: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_ranges(self, "experiment")
        if not all(h > lo for lo, h in zip(self.workspace_low, self.workspace_high)):
            raise ConfigError(
                f"experiment.workspace_high {self.workspace_high} must exceed workspace_low {self.workspace_low}"
            )


def runs(cfg: GeneralizationConfig, base_config: str | None) -> list[TrainRun]:
    box = {"robot.workspace": {"low": list(cfg.workspace_low), "high": list(cfg.workspace_high)}}
    return [
        TrainRun(f"guided/seed{s}", s, cfg.steps, True, base_config, {**cfg.overrides, **box}) for s in range(cfg.seeds)
    ]


def region_distance(xy: np.ndarray, low: tuple[float, float], high: tuple[float, float]) -> float:
    """Distance (m) from point `xy` to the axis-aligned rectangle [low, high] (0 inside)."""
    d = np.maximum(np.maximum(np.asarray(low) - xy, 0.0), xy - np.asarray(high))
    return float(np.linalg.norm(d))


def goal_targets(cfg: GeneralizationConfig, run: TrainRun) -> list[tuple[float, float, float]]:
    """(x, y, distance) of the grid targets within `max_distance` of the training goal region that the arm
    can reach for the place and transport poses (IK) and whose place pose lies inside the box."""
    from mrguide.motion.kinematics import IKError, Kinematics
    from mrguide.robot import load_robot

    env = run_config(run).env
    spec, task, region = load_robot(env.robot), env.task, env.twin.goal_region
    kin = Kinematics(spec)
    lo, hi = spec.workspace.lo, spec.workspace.hi
    m = cfg.max_distance
    xs = np.arange(region.low[0] - m, region.high[0] + m + 1e-9, cfg.grid_step)
    ys = np.arange(region.low[1] - m, region.high[1] + m + 1e-9, cfg.grid_step)
    out = []
    for x in xs:
        for y in ys:
            d = region_distance(np.array([x, y]), region.low, region.high)
            if d > m + 1e-9 or not (lo[0] <= x <= hi[0] and lo[1] <= y <= hi[1]):
                continue
            try:
                for z in (task.object_height, task.lift_height):  # place pose (cube on the table) and transport height
                    kin.ik(np.array([x, y, z]), spec.q_home)
            except IKError:
                continue
            out.append((round(float(x), 4), round(float(y), 4), round(d, 4)))
    return out


def evaluate(run: TrainRun, root: str, cfg: GeneralizationConfig) -> str:
    """Evaluate one trained run on every target (a Ray task); writes `goals.csv` in its directory."""
    from mrguide.deploy.policy import ExportedPolicy
    from mrguide.twin.env import PickPlaceEnv
    from mrguide.twin.rollout import run_episode

    out = run.directory(Path(root))
    if (out / "goals.csv").exists():
        return str(out / "goals.csv")
    env_cfg = run_config(run).env
    env = PickPlaceEnv(env_cfg)
    policy = ExportedPolicy.load(out / "policy.npz", env.robot_spec, env.task_cfg)
    rows = []
    try:
        for i, (x, y, d) in enumerate(goal_targets(cfg, run)):
            seeds = range(EVAL_SEED_BASE + i * cfg.episodes, EVAL_SEED_BASE + (i + 1) * cfg.episodes)
            wins = sum(run_episode(env, policy, s, {"goal": (x, y)}).outcome == "success" for s in seeds)
            rows.append({"x": x, "y": y, "distance_m": d, "episodes": cfg.episodes, "successes": wins})
    finally:
        env.close()
    report.write_report(out, {"goals.csv": report.csv_bytes(rows, ["x", "y", "distance_m", "episodes", "successes"])})
    return str(out / "goals.csv")


def bins(cfg: GeneralizationConfig, goal_rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Success per distance bin over all seeds: targets, episodes, success rate and its Wilson interval."""
    n_bins = int(np.ceil(cfg.max_distance / cfg.bin_width - 1e-9))
    table = []
    for b in range(n_bins):
        lo, hi = b * cfg.bin_width, (b + 1) * cfg.bin_width
        sel = [
            r
            for r in goal_rows
            if (lo <= float(r["distance_m"]) < hi) or (b == n_bins - 1 and float(r["distance_m"]) == hi)
        ]
        episodes = sum(int(r["episodes"]) for r in sel)
        wins = sum(int(r["successes"]) for r in sel)
        ci = wilson(wins, episodes)
        table.append(
            {
                "bin_low_m": round(lo, 3),
                "bin_high_m": round(hi, 3),
                "targets": len({(r["x"], r["y"]) for r in sel}),
                "episodes": episodes,
                "success": round(wins / episodes, 3) if episodes else None,
                "ci_low": round(ci[0], 3),
                "ci_high": round(ci[1], 3),
            }
        )
    return table


def generalization_report(cfg: GeneralizationConfig, root: Path, run_list: list[TrainRun]) -> dict[str, bytes]:
    goal_rows: list[dict[str, Any]] = []  # goals.csv's rows (strings) and the run's seed
    for run in run_list:
        with (run.directory(root) / "goals.csv").open() as fh:
            goal_rows += [{**r, "seed": run.seed} for r in csv.DictReader(fh)]
    table = bins(cfg, goal_rows)
    md = (
        f"Generalization: {cfg.seeds} guided seeds × {cfg.steps} steps (workspace low={list(cfg.workspace_low)} "
        f"high={list(cfg.workspace_high)}), {cfg.episodes} episodes per target per seed, targets on a {cfg.grid_step} m "
        f"grid binned by distance to the training goal region; 95 % Wilson intervals. Paper: > 90 % near the region, "
        f"< 20 % at 0.18 m.\n\n"
        + report.markdown(
            table,
            [
                ("bin_low_m", "from (m)"),
                ("bin_high_m", "to (m)"),
                ("targets", "targets"),
                ("episodes", "episodes"),
                ("success", "success"),
                ("ci_low", "95 % CI low"),
                ("ci_high", "95 % CI high"),
            ],
        )
    )
    return {
        "summary.csv": report.csv_bytes(
            table, ["bin_low_m", "bin_high_m", "targets", "episodes", "success", "ci_low", "ci_high"]
        ),
        "goals.csv": report.csv_bytes(goal_rows, ["seed", "x", "y", "distance_m", "episodes", "successes"]),
        "summary.md": md.encode(),
        "fig6_generalization.png": _figure(table),
    }


def _figure(table: list[dict[str, Any]]) -> bytes:
    fig, ax = report.figure(
        "Generalization vs distance from the training region (Fig. 6)",
        "distance of the goal from the training goal region (m)",
        "success rate",
    )
    mid = np.array([(t["bin_low_m"] + t["bin_high_m"]) / 2 for t in table])
    p = np.array([t["success"] if t["success"] is not None else np.nan for t in table])
    ax.plot(mid, p, "o-", color="tab:red", label="ours")
    ax.fill_between(
        mid,
        [t["ci_low"] for t in table],
        [t["ci_high"] for t in table],
        color="tab:red",
        alpha=0.2,
        label="95 % Wilson CI",
    )
    for m, t in zip(mid, table):
        ax.annotate(f"n={t['targets']}", (m, 0.02), ha="center", fontsize=7)
    ax.plot([mid[0]], [PAPER_NEAR], "^", color=report.PAPER_COLOR, label="paper: > 90 % near the region")
    ax.plot([PAPER_FAR_AT], [PAPER_FAR], "v", color=report.PAPER_COLOR, label="paper: < 20 % at 0.18 m")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(loc="upper right")
    return report.png_bytes(fig)


register(
    "generalization",
    Experiment(
        GeneralizationConfig,
        "generalization.toml",
        "runs/generalization",
        runs,
        lambda c, b, r, e: generalization_report(c, r, runs(c, b)),
        "Fig. 6: success on goals beyond the training region",
        evaluate,
        lambda run, root: run.directory(root) / "goals.csv",
    ),
)
