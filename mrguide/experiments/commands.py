"""`mrguide experiment {learning-curves, long-baseline, noise-robustness, generalization, report}`: the paper's
experiments on Ray.

Each experiment reads `[experiment]` of a TOML file under configs/experiments/, trains what is not done
yet (one Ray task per run), then writes its report (CSV, markdown, PNG) from the run directories.
`report` rebuilds a report from the files alone.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path
from collections.abc import Callable
from typing import Any

from mrguide.cli_args import positive_int
from mrguide.config import ConfigError, load_section
from mrguide.experiments.runs import configs

CONFIG_DIR = Path(__file__).resolve().parents[2] / "configs" / "experiments"


@dataclass(frozen=True)
class Experiment:
    """How to run and report one experiment: its config class and file, its runs, an optional evaluation of
    the trained runs (Ray tasks), and its report built from the run directories."""

    config_cls: type
    default_config: str
    default_out: str
    runs: Callable[[Any, str | None], list]
    report: Callable[[Any, str | None, Path, int], dict[str, bytes]]
    evaluate: Callable[..., None] | None = None


def _experiments() -> dict[str, Experiment]:
    from mrguide.experiments import generalization as gen
    from mrguide.experiments import learning_curves as lc
    from mrguide.experiments import noise_robustness as nr

    return {
        "learning-curves": Experiment(lc.CurvesConfig, "learning_curves.toml", "runs/learning-curves", lc.runs,
                                      lambda c, b, r, e: lc.learning_curves_report(c, lc.records(c, b, r, e))),
        "long-baseline": Experiment(lc.CurvesConfig, "long_baseline.toml", "runs/long-baseline", lc.runs,
                                    lambda c, b, r, e: lc.long_baseline_report(c, lc.records(c, b, r, e))),
        "noise-robustness": Experiment(nr.NoiseConfig, "noise_robustness.toml", "runs/noise-robustness", nr.runs,
                                       lambda c, b, r, e: nr.noise_report(c, nr.records(c, b, r, e))),
        "generalization": Experiment(gen.GeneralizationConfig, "generalization.toml", "runs/generalization", gen.runs,
                                     lambda c, b, r, e: gen.generalization_report(c, r, gen.runs(c, b)), _evaluate_goals),
    }


def _evaluate_goals(cfg: Any, base: str | None, out: Path, workers: int, address: str | None, show_progress: bool) -> None:
    """Fig. 6: every trained run on the goal grid (one Ray task per run; a run with its goals.csv is skipped)."""
    from mrguide.experiments import generalization as gen
    from mrguide.experiments.execution import map_tasks

    todo = [r for r in gen.runs(cfg, base) if not (r.directory(out) / "goals.csv").exists()]
    map_tasks(gen.evaluate, [(r, str(out), cfg) for r in todo], workers, address, "goal grid", show_progress)


NAMES = ("learning-curves", "long-baseline", "noise-robustness", "generalization")


def add_experiment_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("experiment", help="the paper's experiments (Fig. 3-7, 9), run on Ray, resumable")
    esub = p.add_subparsers(dest="experiment", required=True)
    for name in NAMES:
        e = esub.add_parser(name, help=f"{name}: train what is not done yet, then report")
        e.add_argument("--config", help=f"experiment TOML ([experiment]); default configs/experiments/<{name}>.toml")
        e.add_argument("--out", help="experiment directory (one subdirectory per run); default runs/<name>")
        e.add_argument("--seeds", type=positive_int, help="override experiment.seeds")
        e.add_argument("--steps", type=positive_int, help="override experiment.steps")
        e.add_argument("--workers", type=positive_int, default=2, help="local Ray: CPUs (= runs at a time)")
        e.add_argument("--address", help="an existing Ray cluster: 'auto' on a cluster node, or ray://HEAD:10001")
        e.add_argument("--quiet", action="store_true")
        e.set_defaults(func=cmd_experiment, name=name)
    r = esub.add_parser("report", help="rebuild an experiment's report from its run directories (no training)")
    r.add_argument("name", choices=NAMES)
    r.add_argument("--config", help="the experiment TOML the runs were made with")
    r.add_argument("--out", help="experiment directory")
    r.add_argument("--seeds", type=positive_int)
    r.add_argument("--steps", type=positive_int)
    r.set_defaults(func=cmd_report)


def _setup(args: argparse.Namespace) -> tuple[Experiment, Any, str | None, Path]:
    exp = _experiments()[args.name]
    path = Path(args.config) if args.config else CONFIG_DIR / exp.default_config
    cfg = load_section(exp.config_cls, path, "experiment")
    cfg = dataclasses.replace(cfg, **{k: getattr(args, k) for k in ("seeds", "steps") if getattr(args, k) is not None})
    base = None
    if cfg.config:
        base_path = (path.parent / cfg.config).resolve()
        if not base_path.is_file():
            raise ConfigError(f"{path} [experiment]: config = {cfg.config!r}: no such file {base_path}")
        base = str(base_path)
    out = Path(args.out or exp.default_out)
    for run in exp.runs(cfg, base):  # every run's configuration is checked before anything starts
        configs(run, f"{path} [experiment]")
    return exp, cfg, base, out


def cmd_experiment(args: argparse.Namespace) -> int:
    from mrguide.experiments.execution import ExperimentError, run_all

    exp, cfg, base, out = _setup(args)
    specs = exp.runs(cfg, base)
    try:
        run_all(specs, out, args.workers, args.address, show_progress=not args.quiet)
        if exp.evaluate is not None:
            exp.evaluate(cfg, base, out, args.workers, args.address, not args.quiet)
    except ExperimentError as exc:
        print(f"mrguide experiment {args.name}: {exc}", file=sys.stderr)
        return 1
    return _write_report(exp, cfg, base, out)


def cmd_report(args: argparse.Namespace) -> int:
    exp, cfg, base, out = _setup(args)
    missing = [r.name for r in exp.runs(cfg, base) if not (r.directory(out) / "done").exists()
               or (exp.evaluate is not None and not (r.directory(out) / "goals.csv").exists())]
    if missing:
        raise ConfigError(f"{out}: {len(missing)} runs are not finished (e.g. {missing[0]}); run the experiment to finish them")
    return _write_report(exp, cfg, base, out)


def _write_report(exp: Experiment, cfg: Any, base: str | None, out: Path) -> int:
    from mrguide.experiments.report import write_report

    eval_episodes = configs(exp.runs(cfg, base)[0])[0].eval_episodes
    files = exp.report(cfg, base, out, eval_episodes)
    write_report(out, files)
    print(files["summary.md"].decode())
    print(f"report and figures in {out}")
    return 0
