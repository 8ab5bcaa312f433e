"""Parts a person teaches to grip: every mark over the live protocol (the annotation bot with the person's error model),
for each part of the library not gripped at its middle, then each final policy judged on fresh episodes.

Each part trains with its shipped config (`configs/parts/<part>.toml`) and the person's `[guidance]` (the experiment's
`person` file). The person teaches where they grip the part ("not there — here") and, shown the grip the cell then
uses (the status's `grasp`), steps in to correct one they see wrong; beside it, on fewer seeds, the same
person marking without teaching, read under the centre prior as before a person could teach: the comparison. The
judge (`part_grasps`) reads each final policy's grasps and places; the runs' marks, robot time and part resets come
from their `metrics.csv`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Annotated, Any

import numpy as np

from mrguide.config import ConfigError, ConfigFile, Range, check_ranges
from mrguide.experiments import report
from mrguide.experiments.registry import Experiment, register
from mrguide.experiments.run_records import read_run
from mrguide.experiments.train_runs import TrainRun, run_config
from mrguide.parts import PARTS

VARIANTS = ("taught", "centre_prior")


@dataclass(frozen=True)
class PartsConfig:
    """[experiment] of configs/experiments/parts.toml."""

    parts: tuple[str, ...] = ("hole_plate", "l_bracket", "keepout_block")
    seeds: Annotated[int, Range(1, 1000)] = 10
    centre_prior_seeds: Annotated[int, Range(0, 1000)] = 3  # the comparison's seeds, per part
    steps: Annotated[int, Range(1, 10**8)] = 20_000
    #: The person: a training config whose [guidance] is theirs, relative to the experiment file.
    config: str = "../runs/person.toml"
    episodes: Annotated[int, Range(1, 10**5)] = 50  # fresh episodes per final policy, judged
    overrides: dict[str, Any] = field(default_factory=dict)  # every run's, over the part's file and the person

    def __post_init__(self) -> None:
        check_ranges(self, "experiment")
        unknown = [p for p in self.parts if p not in PARTS]
        if unknown or not self.parts:
            raise ConfigError(f"experiment.parts: {unknown or 'none'}: expected some of {', '.join(PARTS)}")


def _person(path: str | None) -> dict[str, Any]:
    """The person's [guidance] of file `path` as dotted overrides ("guidance.noise.sigma_along" → 0.02, ...)."""

    def flat(prefix: str, table: dict[str, Any]) -> dict[str, Any]:
        out: dict[str, Any] = {}
        for key, value in table.items():
            out |= flat(f"{prefix}.{key}", value) if isinstance(value, dict) else {f"{prefix}.{key}": value}
        return out

    return flat("guidance", ConfigFile.read(path).tables.get("guidance", {}))


def runs(cfg: PartsConfig, base_config: str | None) -> list[TrainRun]:
    """Every part, taught on `seeds` seeds and marked under the centre prior on `centre_prior_seeds`, over the wire."""
    from mrguide.shipped_configs import shipped_config

    person = _person(base_config)
    out = []
    for part in cfg.parts:
        config = str(shipped_config("parts", f"{part}.toml"))
        for variant, seeds in zip(VARIANTS, (cfg.seeds, cfg.centre_prior_seeds)):
            overrides = person | cfg.overrides | {"guidance.noise.teaches": variant == "taught"}
            out += [
                TrainRun(f"{part}/{variant}/seed{s}", s, cfg.steps, True, config, overrides, "bot")
                for s in range(seeds)
            ]
    return out


def judged_path(run: TrainRun, root: Path) -> Path:
    return run.directory(root) / "judged.csv"


def evaluate(run: TrainRun, root: str, cfg: PartsConfig) -> str:
    """The judge on the final policy's `episodes` fresh episodes (a Ray task)."""
    from mrguide.experiments.part_grasps import FIELDS, judged_episodes

    out = judged_path(run, Path(root))
    if not out.exists():
        rows = judged_episodes(run.directory(Path(root)) / "policy.npz", run_config(run).env, cfg.episodes)
        report.write_report(out.parent, {out.name: report.csv_bytes([asdict(r) for r in rows], list(FIELDS))})
    return str(out)


def _row(run: TrainRun, root: Path, episodes_per_eval: int) -> dict[str, Any]:
    """One run: convergence, what the person gave, what the cell spent, and the judge's reading."""
    rec = read_run(run, root, episodes_per_eval)
    judged = report.read_csv(judged_path(run, root))
    return {
        "part": run.name.split("/")[0],
        "variant": run.name.split("/")[1],
        "seed": run.seed,
        "convergence_step": rec.converged.step,
        "marks_until_convergence": rec.annotations_until_convergence,
        "marks_total": rec.annotations_total,
        "corrections_total": rec.corrections,
        "robot_min_until_convergence": rec.robot_min_until_convergence,
        "resets_until_convergence": rec.resets_until_convergence,
        "probes_total": rec.probes,
        "grasp_acceptable": np.mean([r["grasp_acceptable"] == "True" for r in judged]),
        "placed": np.mean([r["placed"] == "True" for r in judged]),
        "both": np.mean([r["grasp_acceptable"] == "True" and r["placed"] == "True" for r in judged]),
    }


def _summary(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    out = []
    for part, variant in sorted({(r["part"], r["variant"]) for r in rows}):
        mine = [r for r in rows if (r["part"], r["variant"]) == (part, variant)]
        conv = [r for r in mine if r["convergence_step"] is not None]

        def median(key: str, among: list[dict[str, Any]] = conv) -> float | None:
            return round(float(np.median([r[key] for r in among])), 3) if among else None

        out.append(
            {"part": part, "variant": variant, "seeds": len(mine), "converged": len(conv)}
            | {k: median(k) for k in ("marks_until_convergence", "robot_min_until_convergence")}
            | {k: median(k) for k in ("resets_until_convergence",)}
            | {f"{k}_median": median(k, mine) for k in ("marks_total", "corrections_total")}
            | {f"{k}_median": median(k, mine) for k in ("grasp_acceptable", "placed", "both")}
            | {"both_min": round(min(r["both"] for r in mine), 3)}
        )
    return out


def parts_report(cfg: PartsConfig, base: str | None, root: Path, episodes_per_eval: int) -> dict[str, bytes]:
    """summary.csv, runs.csv and summary.md."""
    rows = [_row(r, root, episodes_per_eval) for r in runs(cfg, base)]
    for r in rows:
        r.update({k: round(float(r[k]), 3) for k in ("grasp_acceptable", "placed", "both")})
    summary = _summary(rows)
    intro = (
        f"Parts a person teaches to grip, every mark over the wire (the annotation bot, the person of {cfg.config}): "
        f"{cfg.seeds} seeds taught and {cfg.centre_prior_seeds} marked under the centre prior per part, "
        f"{cfg.steps} steps; convergence with the learning-curves rule; every final policy judged on {cfg.episodes} "
        "fresh episodes (grasp in the part's acceptable region, part at its place). Marks count every answer, the "
        "corrections among them (the person stepped in on a grip they saw wrong, and taught it anew).\n\n"
    )
    return report.summary_files(intro, summary, [(k, k.replace("_", " ")) for k in summary[0]], rows)


register(
    "parts",
    Experiment(
        PartsConfig,
        "parts.toml",
        "runs/parts",
        runs,
        parts_report,
        "parts a person teaches to grip (hole plate, L-bracket, keep-out block), every mark over the wire",
        evaluate,
        judged_path,
    ),
)
