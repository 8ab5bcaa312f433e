"""Noise robustness (paper Fig. 7): convergence probability of guided training as a function of the
annotation noise σ.

Two readings of "perturbing expert actions with Gaussian noise" (Sec. V-E), chosen by `reading`:
- "marks" (the one our target is on): every mark a person makes is off by an isotropic Gaussian error of σ
  per axis (the simulated MR annotator); the marks are fused and bounded by Eq. 13 as any marks are;
- "stored": the arm follows the exact marks, and every stored expert action is perturbed afresh after
  Eq. 13 (label noise), so no reference can bound it.
And beside the paper: "bias", a person's registration bias of σ per axis drawn once per run (on top of the base
config's person: configs/experiments/noise_robustness_bias.toml).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from mrguide.config import ConfigError, Range, check_number, check_ranges
from mrguide.experiments import report
from mrguide.experiments.registry import Experiment, register
from mrguide.experiments.run_records import RunRecord, read_run
from mrguide.experiments.stats import person_minutes, wilson
from mrguide.experiments.train_runs import TrainRun

READINGS = ("marks", "stored", "bias")
#: The config key each reading's σ sets.
NOISE_KEYS = {"marks": "guidance.noise.sigma", "stored": "guidance.action_noise", "bias": "guidance.noise.bias_sigma"}
#: The paper's Fig. 7 in words: 75-85 % up to σ = 0.05 m, more than two thirds at 0.07 m.
PAPER_BAND = (0.75, 0.85, 0.05)
PAPER_AT_007 = 2 / 3


@dataclass(frozen=True)
class NoiseConfig:
    """[experiment] of configs/experiments/noise_robustness.toml."""

    seeds: Annotated[int, Range(1, 1000)] = 10  # paper: 10
    steps: Annotated[int, Range(1, 10**8)] = 20_000  # "within the training horizon": 20k
    sigmas: tuple[float, ...] = (0.0, 0.01, 0.02, 0.03, 0.05, 0.07, 0.1)  # m (the paper's Fig. 7 range)
    reading: str = "marks"  # ours: a person's marks, each off by σ per axis
    config: str = ""  # base training config (TOML), relative to the experiment file; "" = defaults
    overrides: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_ranges(self, "experiment")
        if not self.sigmas:
            raise ConfigError("experiment.sigmas: give at least one noise level (m)")
        for i, s in enumerate(self.sigmas):
            check_number(f"experiment.sigmas[{i}]", s, 0.0, 1.0, " m")
        if self.reading not in READINGS:
            raise ConfigError(f"experiment.reading = {self.reading!r}: expected one of {', '.join(READINGS)}")


def _noise(reading: str, sigma: float) -> dict[str, Any]:
    return {NOISE_KEYS[reading]: sigma}


def runs(cfg: NoiseConfig, base_config: str | None) -> list[TrainRun]:
    """Seed by seed, every σ within: an experiment stopped early still covers every noise level."""
    return [
        TrainRun(_name(sigma, s), s, cfg.steps, True, base_config, {**cfg.overrides, **_noise(cfg.reading, sigma)})
        for s in range(cfg.seeds)
        for sigma in cfg.sigmas
    ]


def _name(sigma: float, seed: int) -> str:
    return f"sigma_{sigma:.3f}/seed{seed}"


def records(
    cfg: NoiseConfig, base_config: str | None, root: Path, episodes_per_eval: int
) -> dict[float, list[RunRecord]]:
    """Run records grouped by σ."""
    by_name = {r.name: r for r in runs(cfg, base_config)}
    return {
        sigma: [read_run(by_name[_name(sigma, s)], root, episodes_per_eval) for s in range(cfg.seeds)]
        for sigma in cfg.sigmas
    }


#: summary.md's columns: (key, header).
SUMMARY_COLUMNS = (
    ("sigma_m", "σ (m)"),
    ("seeds", "seeds"),
    ("converged", "converged"),
    ("probability", "probability"),
    ("ci_low", "95 % CI low"),
    ("ci_high", "95 % CI high"),
    ("median_step", "median step"),
    ("median_annotations", "annotations until convergence (median)"),
    ("median_person_minutes", "person-minutes until convergence (median)"),
    ("median_marks_total", "marks per run (median)"),
    ("median_person_minutes_total", "person-minutes per run (median)"),
    ("reached_at_end", "reached only at the end"),
)
#: summary.csv's columns (convergence, then the marks per run).
SUMMARY_CSV = (
    "sigma_m",
    "seeds",
    "converged",
    "probability",
    "median_annotations",
    "median_person_minutes",
    "median_marks_total",
    "median_person_minutes_total",
)


def _level_row(sigma: float, rs: list[RunRecord]) -> dict[str, Any]:
    """One σ's line of the summary: convergence with its Wilson interval, marks until convergence and per run."""
    conv = [r for r in rs if r.converged.step is not None]
    lo, hi = wilson(len(conv), len(rs))
    ann = [a for r in conv if (a := r.annotations_until_convergence) is not None]  # all of them: converged
    total = float(np.median([r.annotations_total for r in rs]))
    return {
        "sigma_m": sigma,
        "seeds": len(rs),
        "converged": len(conv),
        "probability": round(len(conv) / len(rs), 3),
        "median_annotations": int(np.median(ann)) if ann else None,
        "median_person_minutes": person_minutes(float(np.median(ann))) if ann else None,
        "median_marks_total": int(total),
        "median_person_minutes_total": person_minutes(total),
        "ci_low": round(lo, 3),
        "ci_high": round(hi, 3),
        "median_step": int(np.median([r.converged.step for r in conv])) if conv else None,
        "reached_at_end": sum(r.converged.at_end for r in rs),
    }


def _run_row(sigma: float, r: RunRecord, reading: str) -> dict[str, Any]:
    """One run's line of runs.csv; for the bias reading, with the bias its simulated person drew."""
    row: dict[str, Any] = {
        "sigma_m": sigma,
        "seed": r.run.seed,
        "convergence_step": r.converged.step,
        "reached_at_end": int(r.converged.at_end),
        "annotations_until_convergence": r.annotations_until_convergence,
        "annotations_total": r.annotations_total,
        "person_minutes_total": person_minutes(r.annotations_total),
        "final_eval_success": float(r.eval_rates[-1]),
        "exploring_no_grasp": r.exploring_outcomes["no_grasp"],
        "exploring_dropped": r.exploring_outcomes["dropped"],
    }
    if reading == "bias":
        row["registration_bias_mm"] = " ".join(f"{b:.1f}" for b in registration_bias_mm(r.run))
    return row


def registration_bias_mm(run: TrainRun) -> np.ndarray:
    """The registration bias (mm, x y z) that the simulated person of `run` drew for its whole run: its annotator
    built from the run's configuration and seed as the trainer builds it (`IN_PROCESS_SOURCES["annotator"]`)."""
    from mrguide.experiments.train_runs import run_config
    from mrguide.policies.experts import ANNOTATOR_SEED_OFFSET, SimulatedAnnotator
    from mrguide.robot import load_robot

    cfg = run_config(run)
    gc, ec = cfg.guidance, cfg.env
    person = SimulatedAnnotator(
        ec.task, gc.noise, load_robot(ec.robot).workspace, seed=run.seed + ANNOTATOR_SEED_OFFSET
    )
    return 1e3 * person.run_bias


def noise_report(cfg: NoiseConfig, recs: dict[float, list[RunRecord]]) -> dict[str, bytes]:
    """summary.csv, runs.csv, summary.md and Fig. 7 (or, for the bias reading, its figure beside the paper)."""
    table = [_level_row(sigma, rs) for sigma, rs in recs.items()]
    runs_rows = [_run_row(s, r, cfg.reading) for s, rs in recs.items() for r in rs]
    paper = (
        " Paper: 75–85 % up to 0.05 m, more than two thirds at 0.07 m."
        if cfg.reading != "bias"
        else " Not in the paper."
    )
    md = (
        f"Noise robustness (reading: {cfg.reading}): {cfg.seeds} guided seeds × {cfg.steps} steps per σ; convergence "
        f"within the horizon with the learning-curves rule; 95 % Wilson intervals.{paper}\n\n"
        + report.markdown(table, list(SUMMARY_COLUMNS))
    )
    return {
        "summary.csv": report.csv_bytes(table, list(SUMMARY_CSV)),
        "runs.csv": report.csv_bytes(runs_rows, list(runs_rows[0])),
        "summary.md": md.encode(),
        "fig7_noise_robustness.png": _figure(table, cfg.reading),
    }


def _figure(table: list[dict[str, Any]], reading: str) -> bytes:
    title = (
        "Convergence under a person's registration bias"
        if reading == "bias"
        else f"Convergence under noisy expert actions (Fig. 7, reading: {reading})"
    )
    x_label = "registration bias σ per axis (m)" if reading == "bias" else "noise σ per axis (m)"
    fig, ax = report.figure(title, x_label, "convergence probability")
    x = np.array([t["sigma_m"] for t in table])
    p = np.array([t["probability"] for t in table])
    ax.errorbar(
        x,
        p,
        yerr=[p - [t["ci_low"] for t in table], [t["ci_high"] for t in table] - p],
        fmt="o-",
        color="tab:red",
        capsize=3,
        label="ours, 95 % Wilson CI",
    )
    if reading != "bias":
        lo, hi, up_to = PAPER_BAND
        ax.fill_between([0.0, up_to], lo, hi, color=report.PAPER_COLOR, alpha=0.2, label="paper: 75–85 % up to 0.05 m")
        ax.plot(
            [0.07],
            [PAPER_AT_007],
            marker="^",
            color=report.PAPER_COLOR,
            linestyle="none",
            label="paper: > 2/3 at 0.07 m",
        )
    ax.set_ylim(-0.02, 1.02)
    ax.legend(loc="lower left")
    return report.png_bytes(fig)


register(
    "noise-robustness",
    Experiment(
        NoiseConfig,
        "noise_robustness.toml",
        "runs/noise-robustness",
        runs,
        lambda c, b, r, e: noise_report(c, records(c, b, r, e)),
        "Fig. 7: convergence against the noise on the marks (or a registration bias)",
    ),
)
