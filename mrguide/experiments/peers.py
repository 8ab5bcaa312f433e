"""The peer, side by side: guided DDPG (the default learner) against the RLPD / HIL-SERL-style SAC
(`mrguide.policies.sac`) on the same twin, the same expert source (a person's error model by default) and the
same threshold activation, seed by seed.

Compared at equal marks and at equal wall time: each learner's evaluation success as it stood when its run
had asked `marks_budget` marks, and when it had trained `time_budget_s` seconds; besides convergence, marks
and person-minutes until convergence, and the wall time per run.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from mrguide.config import ConfigError, Range, check_ranges
from mrguide.experiments import report
from mrguide.experiments.registry import Experiment, register
from mrguide.experiments.run_records import RunRecord, read_run
from mrguide.experiments.stats import person_minutes
from mrguide.experiments.train_runs import TrainRun

COLORS = {"ddpg": "tab:red", "sac": "tab:purple"}


@dataclass(frozen=True)
class PeersConfig:
    """[experiment] of configs/experiments/peers.toml."""

    seeds: Annotated[int, Range(1, 1000)] = 10
    steps: Annotated[int, Range(1, 10**8)] = 20_000
    learners: tuple[str, ...] = ("ddpg", "sac")  # the shipped two; any registered learner may be named
    config: str = "../runs/person.toml"  # base training config, relative to the experiment file (the marks in process)
    #: compare the learners' evaluation success after this many marks ...
    marks_budget: Annotated[int, Range(1, 10**6)] = 100
    time_budget_s: Annotated[float, Range(1.0, 1e7, " s")] = 180.0  # ... and after this much training wall time
    overrides: dict[str, Any] = field(default_factory=dict)  # for every learner ("sac.utd" = 4, ...)

    def __post_init__(self) -> None:
        check_ranges(self, "experiment")
        from mrguide.policies.learners import LEARNERS  # the registry (torch): only when an experiment is read

        if not self.learners or any(v not in LEARNERS for v in self.learners):
            raise ConfigError(f"experiment.learners = {list(self.learners)!r}: expected some of {', '.join(LEARNERS)}")


def runs(cfg: PeersConfig, base_config: str | None) -> list[TrainRun]:
    """Seed by seed, every learner within: an experiment stopped early still compares both."""
    return [
        TrainRun(f"{learner}/seed{s}", s, cfg.steps, True, base_config, {**cfg.overrides, "train.learner": learner})
        for s in range(cfg.seeds)
        for learner in cfg.learners
    ]


def records(
    cfg: PeersConfig, base_config: str | None, root: Path, episodes_per_eval: int
) -> dict[str, list[RunRecord]]:
    by_learner: dict[str, list[RunRecord]] = {v: [] for v in cfg.learners}
    for run in runs(cfg, base_config):
        by_learner[run.name.split("/")[0]].append(read_run(run, root, episodes_per_eval))
    return by_learner


def success_at(rec: RunRecord, per_row: np.ndarray, budget: float) -> float:
    """The evaluation success as it stood when `per_row` (marks asked, wall time) first reached `budget`: the latest
    evaluation at or below it (0 before the first); the final evaluation if the run never reached it."""
    at = rec.at_evaluations(per_row)
    within = at <= budget
    return float(rec.eval_rates[within][-1]) if within.any() else 0.0


def wall_until_convergence(rec: RunRecord) -> float | None:
    if rec.converged.step is None:
        return None
    return float(rec.row_wall[rec.row_steps <= rec.converged.step][-1])


def peers_report(cfg: PeersConfig, recs: dict[str, list[RunRecord]]) -> dict[str, bytes]:
    """summary.csv, runs.csv, summary.md and the figure: success against marks and against wall time."""
    rows: list[dict[str, Any]] = []
    table = []
    for learner, rs in recs.items():
        for r in rs:
            rows.append(
                {
                    "learner": learner,
                    "seed": r.run.seed,
                    "convergence_step": r.converged.step,
                    "marks_until_convergence": r.annotations_until_convergence,
                    "wall_s_until_convergence": wall_until_convergence(r),
                    "marks_total": r.annotations_total,
                    f"success_at_{cfg.marks_budget}_marks": success_at(r, r.asked, cfg.marks_budget),
                    f"success_at_{cfg.time_budget_s:g}_s": success_at(r, r.row_wall, cfg.time_budget_s),
                    "final_eval_success": float(r.eval_rates[-1]),
                    "wall_s": r.wall_s,
                    "exploring_no_grasp": r.exploring_outcomes["no_grasp"],
                    "exploring_dropped": r.exploring_outcomes["dropped"],
                    "final_temperature": r.final_temperature,
                }
            )
        mine = [row for row in rows if row["learner"] == learner]
        conv = [row for row in mine if row["convergence_step"] is not None]
        marks = [row["marks_until_convergence"] for row in conv]

        def median(key: str, of: list[dict[str, Any]]) -> float | None:
            return round(float(np.median([row[key] for row in of])), 1) if of else None

        table.append(
            {
                "learner": learner,
                "seeds": len(mine),
                "converged": len(conv),
                "median_step": median("convergence_step", conv),
                "median_marks": median("marks_until_convergence", conv),
                "median_person_minutes": person_minutes(float(np.median(marks))) if marks else None,
                "median_wall_s_until_convergence": median("wall_s_until_convergence", conv),
                f"mean_success_at_{cfg.marks_budget}_marks": round(
                    float(np.mean([r[f"success_at_{cfg.marks_budget}_marks"] for r in mine])), 3
                ),
                f"mean_success_at_{cfg.time_budget_s:g}_s": round(
                    float(np.mean([r[f"success_at_{cfg.time_budget_s:g}_s"] for r in mine])), 3
                ),
                "median_wall_s_per_run": median("wall_s", mine),
                "final_eval_success": round(float(np.mean([r["final_eval_success"] for r in mine])), 3),
            }
        )
    md = (
        f"Peers: {', '.join(cfg.learners)}, {cfg.seeds} seeds × {cfg.steps} steps each, the same expert source and threshold "
        f"activation; success compared after {cfg.marks_budget} marks and after {cfg.time_budget_s:g} s of training.\n\n"
        + report.markdown(table, [(k, k.replace("_", " ")) for k in table[0]])
    )
    return {
        "summary.csv": report.csv_bytes(table, list(table[0])),
        "runs.csv": report.csv_bytes(rows, list(rows[0])),
        "summary.md": md.encode(),
        "peers.png": _figure(recs, cfg),
    }


def _figure(recs: dict[str, list[RunRecord]], cfg: PeersConfig) -> bytes:
    fig, axes = report.figure(
        "Peers: guided DDPG against RLPD-style SAC",
        "marks asked (cumulative)",
        "evaluation success",
        size=(10.0, 4.0),
        columns=2,
    )
    for learner, rs in recs.items():
        for ax, (column, limit) in zip(
            axes,
            (
                ("asked", max(r.annotations_total for rs_ in recs.values() for r in rs_)),
                ("row_wall", max(r.wall_s for rs_ in recs.values() for r in rs_)),
            ),
        ):
            grid = np.linspace(0, limit, 60)
            curves = np.array([[success_at(r, getattr(r, column), g) for g in grid] for r in rs])
            ax.plot(grid, curves.mean(0), color=COLORS[learner], label=f"{learner}, mean of {len(rs)} seeds")
            ax.fill_between(grid, curves.min(0), curves.max(0), color=COLORS[learner], alpha=0.15)
    axes[0].axvline(cfg.marks_budget, color="grey", linestyle=":")
    axes[1].axvline(cfg.time_budget_s, color="grey", linestyle=":")
    axes[1].set_xlabel("training wall time (s)")
    for ax in axes:
        ax.set_ylim(-0.02, 1.02)
        ax.legend(loc="lower right")
    return report.png_bytes(fig)


register(
    "peers",
    Experiment(
        PeersConfig,
        "peers.toml",
        "runs/peers",
        runs,
        lambda c, b, r, e: peers_report(c, records(c, b, r, e)),
        "guided DDPG and the RLPD-style SAC peer side by side",
    ),
)
