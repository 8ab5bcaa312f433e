"""Learning curves: baseline vs guided DDPG over seeds (paper Fig. 3, 5, 9) and the long baseline (Fig. 4).

Both train one run per (variant, seed) and aggregate the runs' files only; the report can be rebuilt
from the run directories at any time (`mrguide experiment report`).
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
from mrguide.experiments.stats import CONVERGENCE_THRESHOLD, PERSON_SECONDS_PER_MARK, WINDOW_EPISODES, person_minutes
from mrguide.experiments.train_runs import TrainRun

VARIANTS = ("baseline", "guided")
COLORS = {"baseline": "tab:blue", "guided": "tab:red"}


@dataclass(frozen=True)
class CurvesConfig:
    """[experiment] of configs/experiments/learning_curves.toml and long_baseline.toml."""

    seeds: Annotated[int, Range(1, 1000)] = 10  # paper: 10
    steps: Annotated[int, Range(1, 10**8)] = 20_000  # paper: 20k (Fig. 3); 100k for the long baseline (Fig. 4)
    variants: tuple[str, ...] = VARIANTS
    config: str = ""  # base training config (TOML), relative to the experiment file; "" = defaults
    overrides: dict[str, Any] = field(default_factory=dict)  # "guidance.noise.sigma" = 0.05, ...

    def __post_init__(self) -> None:
        check_ranges(self, "experiment")
        if not self.variants or any(v not in VARIANTS for v in self.variants):
            raise ConfigError(f"experiment.variants = {list(self.variants)!r}: expected some of {', '.join(VARIANTS)}")


def runs(cfg: CurvesConfig, base_config: str | None) -> list[TrainRun]:
    return [
        TrainRun(f"{v}/seed{s}", s, cfg.steps, v == "guided", base_config, dict(cfg.overrides))
        for v in cfg.variants
        for s in range(cfg.seeds)
    ]


def records(
    cfg: CurvesConfig, base_config: str | None, root: Path, episodes_per_eval: int
) -> dict[str, list[RunRecord]]:
    by_variant: dict[str, list[RunRecord]] = {v: [] for v in cfg.variants}
    for run in runs(cfg, base_config):
        by_variant[run.name.split("/")[0]].append(read_run(run, root, episodes_per_eval))
    return by_variant


def per_run_rows(recs: dict[str, list[RunRecord]]) -> list[dict[str, Any]]:
    return [
        {
            "variant": v,
            "seed": r.run.seed,
            "convergence_step": r.converged.step,
            "reached_at_end": int(r.converged.at_end),
            "annotations_until_convergence": r.annotations_until_convergence,
            "annotations_total": r.annotations_total,
            "final_eval_success": float(r.eval_rates[-1]),
            "wall_s": r.wall_s,
        }
        for v, rs in recs.items()
        for r in rs
    ]


def learning_curves_report(cfg: CurvesConfig, recs: dict[str, list[RunRecord]]) -> dict[str, bytes]:
    """summary.csv, runs.csv, summary.md and Fig. 3, 5, 9."""
    table = _curves_summary_rows(recs)
    md = _curves_summary_md(cfg, table)
    grid = _grid(cfg.steps)
    files = {
        "summary.csv": report.csv_bytes(
            table,
            [
                "variant",
                "seeds",
                "converged_4k",
                "converged_5k",
                "converged_20k",
                "median_step",
                "median_annotations",
                "median_person_minutes",
            ],
        ),
        "runs.csv": report.csv_bytes(per_run_rows(recs), list(per_run_rows(recs)[0])),
        "summary.md": md.encode(),
        "fig3_learning_curves.png": _fig_returns(
            recs, grid, "Learning curves (Fig. 3)", "guided converges within ≈ 5k steps; baseline far from it at 20k"
        ),
        "fig5_convergence.png": _fig_convergence(
            recs, cfg.steps, "guided: nearly all seeds early; baseline: delayed, unreliable"
        ),
    }
    if "guided" in recs:
        files["fig9_expert_effort.png"] = _fig_effort(recs["guided"], grid)
    return files


def _curves_summary_rows(recs: dict[str, list[RunRecord]]) -> list[dict[str, Any]]:
    """One summary row per variant: convergence counts and medians, annotation effort, final success."""
    table = []
    for v, rs in recs.items():
        conv = [r.converged.step for r in rs if r.converged.step is not None]
        ann = [a for r in rs if (a := r.annotations_until_convergence) is not None]  # the converged runs
        table.append(
            {
                "variant": v,
                "seeds": len(rs),
                "converged_4k": sum(c <= 4000 for c in conv),
                "converged_5k": sum(c <= 5000 for c in conv),
                "converged_20k": sum(c <= 20_000 for c in conv),
                "median_step": int(np.median(conv)) if conv else None,
                "median_annotations": int(np.median(ann)) if ann and v == "guided" else None,
                "median_person_minutes": person_minutes(float(np.median(ann))) if ann and v == "guided" else None,
                "reached_at_end": sum(r.converged.at_end for r in rs),
                "final_eval_success": round(float(np.mean([r.eval_rates[-1] for r in rs])), 3),
            }
        )
    return table


def _curves_summary_md(cfg: CurvesConfig, table: list[dict[str, Any]]) -> str:
    """summary.md of the learning curves: how convergence is counted, then the summary table."""
    return (
        f"Learning curves: {cfg.seeds} seeds × {cfg.steps} steps per variant. Convergence: the evaluation success over "
        f"the last {WINDOW_EPISODES} deterministic episodes reaches {CONVERGENCE_THRESHOLD:.0%} (ours) and stays there to "
        "the end; a window first reached at the final evaluation is counted as 'reached at the end', not converged.\n\n"
        + report.markdown(
            table,
            [
                ("variant", "variant"),
                ("seeds", "seeds"),
                ("converged_4k", "converged ≤ 4k"),
                ("converged_5k", "converged ≤ 5k"),
                ("converged_20k", "converged ≤ 20k"),
                ("median_step", "median convergence step"),
                ("median_annotations", "annotations until convergence (median)"),
                (
                    "median_person_minutes",
                    f"person-minutes until convergence (median, {PERSON_SECONDS_PER_MARK:.0f} s a mark)",
                ),
                ("reached_at_end", "reached only at the end"),
                ("final_eval_success", "final eval success"),
            ],
        )
    )


def long_baseline_report(cfg: CurvesConfig, recs: dict[str, list[RunRecord]]) -> dict[str, bytes]:
    """summary.csv, runs.csv, summary.md and Fig. 4."""
    table = []
    for v, rs in recs.items():
        conv = [r.converged.step for r in rs if r.converged.step is not None]
        table.append(
            {
                "variant": v,
                "seeds": len(rs),
                "steps": cfg.steps,
                "converged": len(conv),
                "median_step": int(np.median(conv)) if conv else None,
                "reached_at_end": sum(r.converged.at_end for r in rs),
            }
        )
    md = (
        f"Long-horizon run: {cfg.seeds} seeds × {cfg.steps} steps (paper Fig. 4: 2 of 10 baseline seeds converged "
        "before 100k).\n\n"
        + report.markdown(
            table,
            [
                ("variant", "variant"),
                ("seeds", "seeds"),
                ("steps", "steps"),
                ("converged", "converged"),
                ("median_step", "median convergence step"),
                ("reached_at_end", "reached only at the end"),
            ],
        )
    )
    return {
        "summary.csv": report.csv_bytes(table, ["variant", "seeds", "steps", "converged", "median_step"]),
        "runs.csv": report.csv_bytes(per_run_rows(recs), list(per_run_rows(recs)[0])),
        "summary.md": md.encode(),
        "fig4_long_baseline.png": _fig_returns(
            recs,
            _grid(cfg.steps),
            "Long-horizon baseline (Fig. 4)",
            "return rises slowly; 2 of 10 seeds converge before 100k",
        ),
        "fig5_convergence.png": _fig_convergence(recs, cfg.steps, "2 of 10 baseline seeds by 100k"),
    }


def _grid(steps: int, step: int = 1000) -> np.ndarray:
    step = min(step, steps)
    return np.arange(step, steps + 1, step)


def _ci95(x: np.ndarray) -> np.ndarray:
    """Half-width of the 95 % confidence interval of the mean over axis 0 (Student t)."""
    from scipy import stats as scipy_stats  # here: the CLI imports this module on installs without scipy

    n = x.shape[0]
    return (
        scipy_stats.t.ppf(0.975, n - 1) * np.nanstd(x, axis=0, ddof=1) / np.sqrt(n) if n > 1 else np.zeros(x.shape[1])
    )


def _fig_returns(recs: dict[str, list[RunRecord]], grid: np.ndarray, title: str, paper: str) -> bytes:
    fig, ax = report.figure(title, "training step", "mean return, deterministic evaluation")
    half = int(grid[0]) // 2
    for v, rs in recs.items():
        curves = np.array([r.returns_on(grid, half) for r in rs])
        m, h = np.nanmean(curves, 0), _ci95(curves)
        ax.plot(grid, m, color=COLORS[v], label=f"{v} DDPG, {len(rs)} seeds, 95 % CI")
        ax.fill_between(grid, m - h, m + h, color=COLORS[v], alpha=0.2)
    ax.legend(loc="upper left")
    report.paper_note(ax, paper)
    return report.png_bytes(fig)


def _fig_convergence(recs: dict[str, list[RunRecord]], steps: int, paper: str) -> bytes:
    fig, ax = report.figure(
        f"Convergence (last {WINDOW_EPISODES} eval episodes ≥ {CONVERGENCE_THRESHOLD:.0%} to the end)",
        "normalized training progress",
        "convergence probability",
    )
    x = np.linspace(0, 1, 101)
    for v, rs in recs.items():
        cs = [r.converged.step / steps if r.converged.step is not None else np.inf for r in rs]
        ax.step(x, [np.mean([c <= xi for c in cs]) for xi in x], color=COLORS[v], where="post", label=f"{v} DDPG")
    ax.set_ylim(-0.02, 1.02)
    ax.legend(loc="upper left")
    report.paper_note(ax, paper)
    return report.png_bytes(fig)


def _fig_effort(rs: list[RunRecord], grid: np.ndarray) -> bytes:
    """Fig. 9: expert effort and the realized expert ratio of the guided runs."""
    fig, ax = report.figure(
        "Expert effort and sampling schedule (Fig. 9)", "training step", "annotations asked (cumulative)"
    )
    a = np.array([r.asked_on(grid) for r in rs])
    ax.plot(grid, a.mean(0), color="tab:red", label="cumulative annotations asked")
    ax.fill_between(grid, a.min(0), a.max(0), color="tab:red", alpha=0.2)
    ax.set_ylim(0, max(1.1 * float(a.max()), 1.0))  # from zero: a flat line of two marks is two marks, not a slope
    ax2 = ax.twinx()
    ratio = np.array([r.ratio_on(grid, int(grid[0])) for r in rs])
    ax2.plot(grid, np.nanmean(ratio, 0), color="tab:green", label="realized expert ratio per batch")
    ax2.fill_between(grid, np.nanmin(ratio, 0), np.nanmax(ratio, 0), color="tab:green", alpha=0.2)
    ax2.set(ylabel="expert ratio per batch", ylim=(0, 1))
    handles = ax.get_legend_handles_labels()[0] + ax2.get_legend_handles_labels()[0]
    ax.legend(handles, [h.get_label() for h in handles], loc="center right")
    report.paper_note(ax, "interventions plateau after intake closes at 10k; ratio 0.9 → 0.1")
    return report.png_bytes(fig)


register(
    "learning-curves",
    Experiment(
        CurvesConfig,
        "learning_curves.toml",
        "runs/learning-curves",
        runs,
        lambda c, b, r, e: learning_curves_report(c, records(c, b, r, e)),
        "Fig. 3, 5, 9: guided and baseline learning curves",
    ),
)
register(
    "long-baseline",
    Experiment(
        CurvesConfig,
        "long_baseline.toml",
        "runs/long-baseline",
        runs,
        lambda c, b, r, e: long_baseline_report(c, records(c, b, r, e)),
        "Fig. 4: the baseline over a long run",
    ),
)
