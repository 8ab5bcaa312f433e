"""`mrguide experiment NAME` and `mrguide experiment report NAME`: the paper's experiments on Ray.

Each experiment reads `[experiment]` of a TOML file under configs/experiments/, trains what is not done
yet (one Ray task per run), then writes its report (CSV, markdown, PNG) from the run directories.
`report` rebuilds a report from the files alone.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import sys
from pathlib import Path
from typing import Any

from mrguide.cli_args import add_set_argument, positive_int
from mrguide.config import ConfigError, load_section
from mrguide.experiments.registry import Experiment, experiments
from mrguide.experiments.train_runs import check_same_config, run_config
from mrguide.shipped_configs import shipped_config


def _evaluate(
    exp: Experiment, cfg: Any, base: str | None, out: Path, workers: int, address: str | None, show_progress: bool
) -> None:
    """Every trained run not evaluated yet, one Ray task each (Fig. 6: the goal grid; sim-to-real: three conditions)."""
    from mrguide.experiments.execution import map_tasks

    assert exp.evaluate is not None and exp.evaluated is not None  # called for experiments that evaluate
    todo = [r for r in exp.runs(cfg, base) if not exp.evaluated(r, out).exists()]
    map_tasks(exp.evaluate, [(r, str(out), cfg) for r in todo], workers, address, "evaluation", show_progress)


def add_experiment_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("experiment", help="the paper's experiments (Fig. 3-7, 9), run on Ray, resumable")
    esub = p.add_subparsers(dest="experiment", required=True)
    registered = experiments()
    for name, exp in registered.items():
        e = esub.add_parser(name, help=f"{exp.help}: train what is not done yet, then report")
        e.add_argument(
            "--config", help=f"experiment TOML ([experiment]); default the shipped configs/experiments/<{name}>.toml"
        )
        e.add_argument("--out", help="experiment directory (one subdirectory per run); default runs/<name>")
        e.add_argument("--seeds", type=positive_int, help="override experiment.seeds")
        e.add_argument("--steps", type=positive_int, help="override experiment.steps")
        add_set_argument(
            e,
            "set a training config key for every run, over the file's [experiment.overrides] (e.g. --set "
            "ddpg.lr_actor=0.001); repeatable; what the experiment itself varies it sets last",
        )
        e.add_argument("--workers", type=positive_int, default=2, help="local Ray: CPUs (= runs at a time)")
        e.add_argument("--address", help="an existing Ray cluster: 'auto' on a cluster node, or ray://HEAD:10001")
        e.add_argument("--quiet", action="store_true")
        e.set_defaults(func=cmd_experiment, name=name)
    r = esub.add_parser("report", help="rebuild an experiment's report from its run directories (no training)")
    r.add_argument("name", choices=list(registered))
    r.add_argument("--config", help="the experiment TOML the runs were made with")
    r.add_argument("--out", help="experiment directory")
    r.add_argument("--seeds", type=positive_int)
    r.add_argument("--steps", type=positive_int)
    r.set_defaults(func=cmd_report)


def _setup(args: argparse.Namespace) -> tuple[Experiment, Any, str | None, Path]:
    exp = experiments()[args.name]
    path = Path(args.config) if args.config else shipped_config("experiments", exp.default_config)
    cfg = load_section(exp.config_cls, path, "experiment", known=("experiment",))
    cfg = dataclasses.replace(cfg, **{k: getattr(args, k) for k in ("seeds", "steps") if getattr(args, k) is not None})
    if getattr(args, "set", None):
        cfg = dataclasses.replace(cfg, overrides={**cfg.overrides, **dict(args.set)})
    base = None
    if cfg.config:
        base_path = (path.parent / cfg.config).resolve()
        if not base_path.is_file():
            raise ConfigError(f"{path} [experiment]: config = {cfg.config!r}: no such file {base_path}")
        base = str(base_path)
    for key in ("real_config", "mujoco_config"):  # the cells of the sim-to-real experiment, relative to its file
        if key == "mujoco_config" and not {"mujoco_exact", "mujoco_hmd"} & set(getattr(cfg, "conditions", ())):
            continue  # no condition plays the MuJoCo cell
        if getattr(cfg, key, ""):
            cell = (path.parent / getattr(cfg, key)).resolve()
            if not cell.is_file():
                raise ConfigError(f"{path} [experiment]: {key} = {getattr(cfg, key)!r}: no such file {cell}")
            cfg = dataclasses.replace(cfg, **{key: str(cell)})
    out = Path(args.out or exp.default_out)
    for run in exp.runs(cfg, base):  # every run's configuration is checked before anything starts
        run_config(run, f"{path} [experiment]")
    return exp, cfg, base, out


def cmd_experiment(args: argparse.Namespace) -> int:
    from mrguide.experiments.execution import ExperimentError, ray_session, run_all
    from mrguide.experiments.train_runs import is_done

    exp, cfg, base, out = _setup(args)
    specs = exp.runs(cfg, base)
    for run in specs:  # a run started or done with another configuration is not resumed into this one
        check_same_config(run, out)
    work = [
        r for r in specs if not is_done(r, out) or (exp.evaluated is not None and not exp.evaluated(r, out).exists())
    ]
    try:
        with ray_session(args.workers, args.address) if work else contextlib.nullcontext():
            run_all(specs, out, args.workers, args.address, show_progress=not args.quiet)
            if exp.evaluate is not None:
                _evaluate(exp, cfg, base, out, args.workers, args.address, not args.quiet)
    except ExperimentError as exc:
        print(f"mrguide experiment {args.name}: {exc}", file=sys.stderr)
        return 1
    return _write_report(exp, cfg, base, out)


def cmd_report(args: argparse.Namespace) -> int:
    exp, cfg, base, out = _setup(args)
    missing = [
        r.name
        for r in exp.runs(cfg, base)
        if not (r.directory(out) / "done").exists()
        or (exp.evaluated is not None and not exp.evaluated(r, out).exists())
    ]
    if missing:
        raise ConfigError(
            f"{out}: {len(missing)} runs are not finished (e.g. {missing[0]}); run the experiment to finish them"
        )
    return _write_report(exp, cfg, base, out)


def _write_report(exp: Experiment, cfg: Any, base: str | None, out: Path) -> int:
    from mrguide.experiments.report import write_report

    eval_episodes = run_config(exp.runs(cfg, base)[0]).train.eval_episodes
    files = exp.report(cfg, base, out, eval_episodes)
    write_report(out, files)
    print(files["summary.md"].decode())
    print(f"report and figures in {out}")
    return 0
