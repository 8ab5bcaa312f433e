"""Sim-to-real as an experiment (paper Fig. 8): train guided seeds, then run each exported policy under the
three conditions (`mrguide.experiments.sim2real`) for several evaluation seeds.

Every trained run gets its own `sim2real/` directory with `outcomes.csv` (one row per episode) and the
deploy run logs of conditions 2 and 3; a run whose `outcomes.csv` exists is not evaluated again. The
report pools every training seed's episodes per condition; the spread is over training seeds.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from mrguide.config import ConfigError, Range, check_ranges
from mrguide.experiments import report
from mrguide.experiments.registry import Experiment, register
from mrguide.experiments.train_runs import TrainRun, run_config

CONDITIONS = ("sim", "real_exact", "real_hmd", "mujoco_exact", "mujoco_hmd")
OUTCOME_FIELDS = ["condition", "eval_seed", "episode", "outcome"]


@dataclass(frozen=True)
class Sim2RealConfig:
    """[experiment] of configs/experiments/sim2real.toml."""

    seeds: Annotated[int, Range(1, 1000)] = 3  # training seeds (guided)
    steps: Annotated[int, Range(1, 10**8)] = 20_000
    #: evaluation seeds per policy and condition (object and goal layouts)
    eval_seeds: Annotated[int, Range(1, 1000)] = 3
    episodes: Annotated[int, Range(1, 10_000)] = 10  # per evaluation seed and condition
    conditions: tuple[str, ...] = CONDITIONS
    #: The 'real' cell and the MuJoCo cell, relative to the experiment file (made absolute on load).
    real_config: str = "../cells/real_cell.toml"
    mujoco_config: str = "../cells/mujoco_cell.toml"
    config: str = ""  # base training config (TOML), relative to the experiment file; "" = defaults
    overrides: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_ranges(self, "experiment")
        unknown = [c for c in self.conditions if c not in CONDITIONS]
        if not self.conditions or unknown or len(set(self.conditions)) != len(self.conditions):
            raise ConfigError(
                f"experiment.conditions = {list(self.conditions)}: expected distinct names from {', '.join(CONDITIONS)}"
            )
        if not self.real_config:
            raise ConfigError("experiment.real_config: give the TOML of the 'real' cell")


def runs(cfg: Sim2RealConfig, base_config: str | None) -> list[TrainRun]:
    return [TrainRun(f"guided/seed{s}", s, cfg.steps, True, base_config, dict(cfg.overrides)) for s in range(cfg.seeds)]


def outcomes_path(run: TrainRun, root: Path) -> Path:
    return run.directory(root) / "sim2real" / "outcomes.csv"


def evaluate(run: TrainRun, root: str, cfg: Sim2RealConfig) -> str:
    """One Ray task: the run's exported policy under every condition and evaluation seed; writes outcomes.csv."""
    from mrguide.experiments import sim2real as s2r

    path = outcomes_path(run, Path(root))
    if path.exists():
        return str(path)
    train_cfg = run_config(run).env
    cells = {"real": s2r.load_real_cell(cfg.real_config)}
    if {"mujoco_exact", "mujoco_hmd"} & set(cfg.conditions):
        cells["mujoco"] = s2r.load_real_cell(cfg.mujoco_config)
    policy_file = run.directory(Path(root)) / "policy.npz"
    policy = s2r.load_policy(policy_file, train_cfg, cells["real"])
    rows = []
    for cond in cfg.conditions:
        for seed in range(cfg.eval_seeds):
            if cond == "sim":
                outcomes = s2r.run_sim(policy, train_cfg, seed, cfg.episodes)
            else:
                which, use_hmd = s2r.CELL_CONDITIONS[cond]
                cell = cells[which]
                outcomes = s2r.run_real(
                    policy_file,
                    cell.env,
                    cell.bus,
                    seed,
                    cfg.episodes,
                    path.parent / f"log-{cond}-seed{seed}.jsonl",
                    cell.path,
                    cell.safety,
                    use_hmd=use_hmd,
                    condition=cond,
                )
            rows += [{"condition": cond, "eval_seed": seed, "episode": i, "outcome": o} for i, o in enumerate(outcomes)]
    report.write_report(path.parent, {path.name: report.csv_bytes(rows, OUTCOME_FIELDS)})
    return str(path)


def sim2real_report(cfg: Sim2RealConfig, root: Path, run_list: list[TrainRun]) -> dict[str, bytes]:
    """summary.csv / summary.md / fig8_sim2real.png pooled over training seeds, and every episode in outcomes.csv."""
    from mrguide.experiments import sim2real as s2r
    from mrguide.experiments.sim2real_report import cells_description, report_files

    all_rows, results = [], []
    for cond in cfg.conditions:
        res = s2r.ConditionResult(cond, {})
        for run in run_list:
            rows = [r for r in report.read_csv(outcomes_path(run, root)) if r["condition"] == cond]
            res.outcomes[run.seed] = [r["outcome"] for r in rows]
            all_rows += [{"train_seed": run.seed, **r} for r in rows]
        results.append(res)
    cells = {"real": s2r.load_real_cell(cfg.real_config), "mujoco": s2r.load_real_cell(cfg.mujoco_config)}
    files = report_files(results, cells_description(cells, cfg.conditions))
    intro = (
        f"Sim-to-real: {cfg.seeds} guided training seeds × {cfg.steps} steps, each policy under every condition for "
        f"{cfg.eval_seeds} evaluation seeds × {cfg.episodes} episodes; success pooled over all episodes (95 % Wilson "
        "interval), spread = std over training seeds. Targets (ours): sim ≥ 98 %, real_exact ≥ 95 %, real_hmd ≥ 90 %; "
        "paper: 100 %, 100 %, 86 ± 10 %.\n\n"
    )
    return {
        "summary.csv": files["sim2real.csv"],
        "summary.md": intro.encode() + files["sim2real.md"] + _per_draw(all_rows, cfg).encode(),
        "fig8_sim2real.png": files["fig8_sim2real.png"],
        "outcomes.csv": report.csv_bytes(all_rows, ["train_seed", *OUTCOME_FIELDS]),
    }


def _per_draw(rows: list[dict], cfg: Sim2RealConfig) -> str:
    """A markdown table: per condition, the parts placed per draw (a training seed's policy under one evaluation seed:
    its calibration and its start states), their min and median over the draws."""
    lines = [
        f"\n\nPer draw (a policy under one evaluation seed, {cfg.episodes} episodes):\n",
        "| condition | draws | placed per draw: min | median |",
        "| --- | --- | --- | --- |",
    ]
    for cond in cfg.conditions:
        draws: dict[tuple[str, str], int] = {}
        for r in rows:
            if r["condition"] == cond:
                key = (str(r["train_seed"]), str(r["eval_seed"]))
                draws[key] = draws.get(key, 0) + int(r["outcome"] == "success")
        if draws:
            counts = sorted(draws.values())
            lines.append(f"| {cond} | {len(counts)} | {counts[0]} | {float(np.median(counts)):g} |")
    return "\n".join(lines) + "\n"


register(
    "sim2real",
    Experiment(
        Sim2RealConfig,
        "sim2real.toml",
        "runs/sim2real-experiment",
        runs,
        lambda c, b, r, e: sim2real_report(c, r, runs(c, b)),
        "Fig. 8: train, then every policy in the sim-to-real conditions",
        evaluate,
        outcomes_path,
    ),
)
