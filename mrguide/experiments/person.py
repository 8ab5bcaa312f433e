"""A person's marks: guided training where every mark is made over the live protocol by the annotation bot
with a headset user's errors (`configs/runs/person.toml`: a registration bias drawn once per run, more error
along the line of sight than across it, the odd slip), then every final policy on fresh episodes.

Reported beside Fig. 7's isotropic σ: convergence, marks and person-minutes until convergence, marks over
the run, and the final policies' success on `episodes` start states no evaluation used.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from mrguide.config import Range, check_ranges
from mrguide.experiments import report
from mrguide.experiments.registry import Experiment, register
from mrguide.experiments.run_records import RunRecord, read_run
from mrguide.experiments.stats import PERSON_SECONDS_PER_MARK, person_minutes, wilson
from mrguide.experiments.train_runs import TrainRun, run_config

#: Fresh start states of the final-policy evaluation: env seeds from here, disjoint from training's evaluations (1e6 + …).
FRESH_SEED_BASE = 3_000_000


@dataclass(frozen=True)
class PersonConfig:
    """[experiment] of configs/experiments/person.toml."""

    seeds: Annotated[int, Range(1, 1000)] = 10
    steps: Annotated[int, Range(1, 10**8)] = 20_000
    #: Base training config (its [guidance.noise] is the person), relative to the experiment file.
    config: str = "../runs/person.toml"
    episodes: Annotated[int, Range(1, 10**5)] = 50  # fresh episodes per final policy
    overrides: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_ranges(self, "experiment")


def runs(cfg: PersonConfig, base_config: str | None) -> list[TrainRun]:
    """Every mark over the wire: a live session answered by the annotation bot with the run's error model."""
    return [TrainRun(f"seed{s}", s, cfg.steps, True, base_config, dict(cfg.overrides), "bot") for s in range(cfg.seeds)]


def fresh_path(run: TrainRun, root: Path) -> Path:
    return run.directory(root) / "fresh.csv"


def evaluate(run: TrainRun, root: str, cfg: PersonConfig) -> str:
    """The final policy (the exported file, by the deploy's numpy runner) on `episodes` fresh start states (a Ray task)."""
    from mrguide.deploy.policy import ExportedPolicy
    from mrguide.twin.env import PickPlaceEnv
    from mrguide.twin.rollout import run_episodes

    out = fresh_path(run, Path(root))
    if out.exists():
        return str(out)
    env = PickPlaceEnv(run_config(run).env)
    try:
        policy = ExportedPolicy.load(run.directory(Path(root)) / "policy.npz", env.robot_spec, env.task_cfg)
        summary = run_episodes(env, policy, range(FRESH_SEED_BASE, FRESH_SEED_BASE + cfg.episodes))
    finally:
        env.close()
    rows = [
        {"seed": e.seed, "outcome": e.outcome, "return": round(e.ret, 4), "steps": e.steps} for e in summary.episodes
    ]
    report.write_report(out.parent, {out.name: report.csv_bytes(rows, ["seed", "outcome", "return", "steps"])})
    return str(out)


def fresh_success(run: TrainRun, root: Path) -> float:
    rows = report.read_csv(fresh_path(run, root))
    return float(np.mean([r["outcome"] == "success" for r in rows]))


def _summary(recs: list[RunRecord], fresh: list[float]) -> dict[str, Any]:
    """The panel in one line: convergence with its Wilson interval, marks until convergence and per run, fresh success."""
    conv = [r for r in recs if r.converged.step is not None]
    marks = [a for r in conv if (a := r.annotations_until_convergence) is not None]  # all of them: converged
    lo, hi = wilson(len(conv), len(recs))
    total = float(np.median([r.annotations_total for r in recs]))
    robot = [m for r in conv if (m := r.robot_min_until_convergence) is not None]
    resets = [n for r in conv if (n := r.resets_until_convergence) is not None]
    return {
        "seeds": len(recs),
        "converged": len(conv),
        "ci_low": round(lo, 3),
        "ci_high": round(hi, 3),
        "median_step": int(np.median([r.converged.step for r in conv])) if conv else None,
        "median_marks": int(np.median(marks)) if marks else None,
        "median_person_minutes": person_minutes(float(np.median(marks))) if marks else None,
        "median_marks_total": int(total),
        "median_person_minutes_total": person_minutes(total),
        "median_robot_minutes": round(float(np.median(robot)), 1) if robot else None,
        "median_resets": float(np.median(resets)) if resets else None,
        "fresh_success_median": round(float(np.median(fresh)), 3),
        "fresh_success_min": round(min(fresh), 3),
        "fresh_success_max": round(max(fresh), 3),
    }


def person_report(cfg: PersonConfig, root: Path, run_list: list[TrainRun], episodes_per_eval: int) -> dict[str, bytes]:
    """summary.csv, runs.csv, summary.md and a figure of evaluation success against the marks asked."""
    recs = [read_run(r, root, episodes_per_eval) for r in run_list]
    fresh = [fresh_success(r, root) for r in run_list]
    rows = [
        {
            "seed": rec.run.seed,
            "convergence_step": rec.converged.step,
            "reached_at_end": int(rec.converged.at_end),
            "marks_until_convergence": rec.annotations_until_convergence,
            "person_minutes_until_convergence": person_minutes(rec.annotations_until_convergence),
            "marks_total": rec.annotations_total,
            "person_minutes_total": person_minutes(rec.annotations_total),
            "robot_min_until_convergence": rec.robot_min_until_convergence,
            "resets_until_convergence": rec.resets_until_convergence,
            "final_eval_success": float(rec.eval_rates[-1]),
            f"fresh_success_{cfg.episodes}": f,
            "wall_s": rec.wall_s,
        }
        for rec, f in zip(recs, fresh)
    ]
    summary = [_summary(recs, fresh)]
    intro = (
        f"A person's marks over the wire (the annotation bot): {cfg.seeds} seeds × {cfg.steps} steps; "
        f"convergence with the learning-curves rule; person-minutes at {PERSON_SECONDS_PER_MARK:.0f} s per mark; robot "
        "minutes every decision's 0.1 s, part resets every episode's start; every final "
        f"policy on {cfg.episodes} fresh start states.\n\n"
    )
    columns = [
        ("seeds", "seeds"),
        ("converged", "converged"),
        ("ci_low", "95 % CI low"),
        ("ci_high", "95 % CI high"),
        ("median_step", "median convergence step"),
        ("median_marks", "marks until convergence (median)"),
        ("median_person_minutes", "person-minutes until convergence (median)"),
        ("median_marks_total", "marks per run (median)"),
        ("median_person_minutes_total", "person-minutes per run (median)"),
        ("median_robot_minutes", "robot minutes until convergence (median)"),
        ("median_resets", "part resets until convergence (median)"),
        ("fresh_success_median", f"fresh success, median of {cfg.seeds}"),
        ("fresh_success_min", "min"),
        ("fresh_success_max", "max"),
    ]
    return report.summary_files(intro, summary, columns, rows) | {"person_marks.png": _figure(recs)}


def _figure(recs: list[RunRecord]) -> bytes:
    """Evaluation success (left) and the marks asked (right) by training step, one line per seed; a dot where a
    run converged."""
    fig, (success, marks) = report.figure(
        "A person's marks over the wire", "training step", "evaluation success", size=(11.0, 4.0), columns=2
    )
    for rec in recs:
        (line,) = success.plot(rec.eval_steps, rec.eval_rates, alpha=0.7, label=f"seed {rec.run.seed}")
        marks.plot(rec.row_steps, rec.asked, color=line.get_color(), alpha=0.7)
        if rec.converged.step is not None:
            marks.plot([rec.converged.step], [rec.annotations_until_convergence], "o", color=line.get_color())
    success.set_ylim(-0.02, 1.02)
    success.legend(loc="lower right", ncol=2, fontsize=7)
    marks.set_ylabel("marks asked (cumulative); dot: converged")
    return report.png_bytes(fig)


register(
    "person",
    Experiment(
        PersonConfig,
        "person.toml",
        "runs/person",
        runs,
        lambda c, b, r, e: person_report(c, r, runs(c, b), e),
        "a person's error model, every mark over the live protocol",
        evaluate,
        fresh_path,
    ),
)
