"""`mrguide experiment {learning-curves, long-baseline, noise-robustness, generalization, report}`: the paper's
experiments on Ray; and `mrguide sim2real`, the three sim-to-real conditions (Fig. 8) for one policy.

Each experiment reads `[experiment]` of a TOML file under configs/experiments/, trains what is not done
yet (one Ray task per run), then writes its report (CSV, markdown, PNG) from the run directories.
`report` rebuilds a report from the files alone.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, get_args

from tqdm import tqdm

from mrguide.cli_args import positive_int
from mrguide.config import ConfigError, load_section
from mrguide.experiments.runs import configs, sac_config
from mrguide.shipped_configs import shipped_config

#: The three sim-to-real conditions (run by mrguide.experiments.sim2real; named here to check them without PyBullet).
CONDITIONS = ("sim", "real_exact", "real_hmd", "mujoco_exact", "mujoco_hmd")
#: The paper's three (Fig. 8): what `mrguide sim2real` runs unless --conditions says otherwise.
PAPER_CONDITIONS = CONDITIONS[:3]
GAP_PARAMS = (
    "object_mass",
    "object_friction",
    "suction_break_force",
    "actuator_latency",
    "actuator_lag",
    "joint_noise",
    "vacuum_noise",
)
#: Swept parameters that take whole numbers (control periods).
INTEGER_PARAMS = ("actuator_latency",)
HMD_PARAMS = ("tracking_noise_m", "tracking_noise_deg", "calibration_error_m", "calibration_error_deg")


@dataclass(frozen=True)
class Experiment:
    """How to run and report one experiment: its config class and file, its runs, an optional evaluation of
    the trained runs (Ray tasks), and its report built from the run directories."""

    config_cls: type[Any]
    default_config: str
    default_out: str
    runs: Callable[[Any, str | None], list]
    report: Callable[[Any, str | None, Path, int], dict[str, bytes]]
    #: Ray tasks evaluating each trained run (run, root, cfg) → the file that marks it evaluated
    evaluate: Callable[..., str] | None = None
    evaluated: Callable[[Any, Path], Path] | None = None  # (run, root) → that file


#: The experiments, by the name `mrguide experiment NAME` takes (their `Experiment`s: `_experiments`).
ExperimentName = Literal[
    "learning-curves", "long-baseline", "noise-robustness", "generalization", "person", "peers", "sim2real"
]
NAMES: tuple[ExperimentName, ...] = get_args(ExperimentName)


def _experiments() -> dict[ExperimentName, Experiment]:
    """Every experiment by name, in the order of NAMES (imported here: the parser needs only NAMES)."""
    return {**_figure_experiments(), **_further_experiments()}


def _figure_experiments() -> dict[ExperimentName, Experiment]:
    """Learning curves, long baseline, noise robustness and generalization (the paper's Fig. 3-7)."""
    from mrguide.experiments import generalization as gen
    from mrguide.experiments import learning_curves as lc
    from mrguide.experiments import noise_robustness as nr

    return {
        "learning-curves": Experiment(
            lc.CurvesConfig,
            "learning_curves.toml",
            "runs/learning-curves",
            lc.runs,
            lambda c, b, r, e: lc.learning_curves_report(c, lc.records(c, b, r, e)),
        ),
        "long-baseline": Experiment(
            lc.CurvesConfig,
            "long_baseline.toml",
            "runs/long-baseline",
            lc.runs,
            lambda c, b, r, e: lc.long_baseline_report(c, lc.records(c, b, r, e)),
        ),
        "noise-robustness": Experiment(
            nr.NoiseConfig,
            "noise_robustness.toml",
            "runs/noise-robustness",
            nr.runs,
            lambda c, b, r, e: nr.noise_report(c, nr.records(c, b, r, e)),
        ),
        "generalization": Experiment(
            gen.GeneralizationConfig,
            "generalization.toml",
            "runs/generalization",
            gen.runs,
            lambda c, b, r, e: gen.generalization_report(c, r, gen.runs(c, b)),
            gen.evaluate,
            lambda run, root: run.directory(root) / "goals.csv",
        ),
    }


def _further_experiments() -> dict[ExperimentName, Experiment]:
    """A person's marks, the SAC peer side by side, and sim-to-real (the paper's Fig. 8) as an experiment."""
    from mrguide.experiments import peers, person
    from mrguide.experiments import sim2real_runs as s2r

    return {
        "person": Experiment(
            person.PersonConfig,
            "person.toml",
            "runs/person",
            person.runs,
            lambda c, b, r, e: person.person_report(c, r, person.runs(c, b), e),
            person.evaluate,
            person.fresh_path,
        ),
        "peers": Experiment(
            peers.PeersConfig,
            "peers.toml",
            "runs/peers",
            peers.runs,
            lambda c, b, r, e: peers.peers_report(c, peers.records(c, b, r, e)),
        ),
        "sim2real": Experiment(
            s2r.Sim2RealConfig,
            "sim2real.toml",
            "runs/sim2real-experiment",
            s2r.runs,
            lambda c, b, r, e: s2r.sim2real_report(c, r, s2r.runs(c, b)),
            s2r.evaluate,
            s2r.outcomes_path,
        ),
    }


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
    for name in NAMES:
        e = esub.add_parser(name, help=f"{name}: train what is not done yet, then report")
        e.add_argument(
            "--config", help=f"experiment TOML ([experiment]); default the shipped configs/experiments/<{name}>.toml"
        )
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
    path = Path(args.config) if args.config else shipped_config("experiments", exp.default_config)
    cfg = load_section(exp.config_cls, path, "experiment", known=("experiment",))
    cfg = dataclasses.replace(cfg, **{k: getattr(args, k) for k in ("seeds", "steps") if getattr(args, k) is not None})
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
        configs(run, f"{path} [experiment]")
        sac_config(run, f"{path} [experiment]")
    return exp, cfg, base, out


def cmd_experiment(args: argparse.Namespace) -> int:
    from mrguide.experiments.execution import ExperimentError, run_all

    exp, cfg, base, out = _setup(args)
    specs = exp.runs(cfg, base)
    try:
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

    eval_episodes = configs(exp.runs(cfg, base)[0])[0].eval_episodes
    files = exp.report(cfg, base, out, eval_episodes)
    write_report(out, files)
    print(files["summary.md"].decode())
    print(f"report and figures in {out}")
    return 0


def add_sim2real_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sim2real", help="the three sim-to-real conditions of the paper (Fig. 8) for one policy")
    p.add_argument("--policy", required=True)
    p.add_argument("--config", default=None, help="TOML of the training twin (condition 1); default: built-in defaults")
    p.add_argument(
        "--real-config",
        default=None,
        help="TOML of the 'real' cell: [twin.reality_gap], [deploy] bus_config, [calibration.hmd] (conditions 2, 3)",
    )
    p.add_argument(
        "--mujoco-config",
        default=None,
        help="TOML of the MuJoCo cell (conditions mujoco_exact, mujoco_hmd); default: configs/cells/mujoco_cell.toml",
    )
    p.add_argument("--seeds", type=positive_int, default=3)
    p.add_argument("--episodes", type=positive_int, default=10, help="episodes per seed and condition")
    p.add_argument(
        "--conditions",
        type=conditions_arg,
        default=list(PAPER_CONDITIONS),
        help=f"comma-separated, from {', '.join(CONDITIONS)} (default: the paper's {', '.join(PAPER_CONDITIONS)})",
    )
    p.add_argument(
        "--sweep",
        type=sweep_arg,
        action="append",
        default=[],
        metavar="PARAM=v1,v2,...",
        help=f"instead of the three conditions, success vs one parameter; reality gap ({', '.join(GAP_PARAMS)}) "
        f"runs condition 2, HMD ({', '.join(HMD_PARAMS)}) condition 3; repeatable",
    )
    p.add_argument(
        "--no-recovery",
        action="store_true",
        help="a safety stop ends the seed's run (its remaining episodes fail); default: fault reset, "
        "the stopped episode fails, the next one runs",
    )
    p.add_argument("--out", default="runs/sim2real")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_sim2real)


def conditions_arg(text: str) -> list[str]:
    """argparse type of --conditions: a comma-separated, non-empty list of known conditions, each once."""
    conditions = [c.strip() for c in text.split(",") if c.strip()]
    unknown = [c for c in conditions if c not in CONDITIONS]
    if not conditions or unknown or len(set(conditions)) != len(conditions):
        raise argparse.ArgumentTypeError(f"expected distinct conditions from {', '.join(CONDITIONS)}, got {text!r}")
    return conditions


def sweep_arg(text: str) -> tuple[str, list[float]]:
    """argparse type of --sweep: PARAM=v1,v2,... with a known parameter and finite numbers (whole numbers for
    actuator_latency). Ranges are checked against the configuration (`_check_sweeps`)."""
    name, _, values = text.partition("=")
    if name not in GAP_PARAMS + HMD_PARAMS or not values:
        raise argparse.ArgumentTypeError(
            f"expected PARAM=v1,v2,... with PARAM one of {', '.join(GAP_PARAMS + HMD_PARAMS)}, got {text!r}"
        )
    try:
        numbers = [float(v) for v in values.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: values must be numbers") from None
    if not all(math.isfinite(v) for v in numbers):
        raise argparse.ArgumentTypeError(f"{text!r}: values must be finite")
    if name in INTEGER_PARAMS:
        if any(v != int(v) for v in numbers):
            raise argparse.ArgumentTypeError(f"{text!r}: {name} takes whole numbers")
        numbers = [int(v) for v in numbers]
    return name, numbers


def cmd_sim2real(args: argparse.Namespace) -> int:
    """Every input is checked before the first episode: configs, bus, policy (against both twins), swept values,
    the output directory."""
    from mrguide.experiments import sim2real as s2r
    from mrguide.output_files import check_output_dir
    from mrguide.twin.env import EnvConfig

    out = check_output_dir(args.out, "--out")
    train_cfg = EnvConfig.load(args.config)
    cell = s2r.load_real_cell(args.real_config or shipped_config("cells", "real_cell.toml"))
    cells = {"real": cell}
    if {"mujoco_exact", "mujoco_hmd"} & set(args.conditions):
        cells["mujoco"] = s2r.load_real_cell(args.mujoco_config or shipped_config("cells", "mujoco_cell.toml"))
    real_cfg, real_path, hmd = cell.env, cell.path, cell.hmd
    policy = s2r.load_policy(args.policy, train_cfg, cell)
    _check_sweeps(args.sweep, real_cfg, hmd)
    runs = (
        [(c, None, None) for c in args.conditions]
        if not args.sweep
        else [
            ("real_hmd" if name in HMD_PARAMS else "real_exact", name, v) for name, values in args.sweep for v in values
        ]
    )
    out.mkdir(parents=True, exist_ok=True)
    total = len(runs) * args.seeds * args.episodes
    with tqdm(total=total, desc="sim2real", unit="ep", disable=args.quiet) as bar:
        results = []
        for cond, name, value in runs:
            bar.set_description(f"sim2real {cond}" + (f" {name}={value}" if name else ""))
            res = s2r.ConditionResult(cond if name is None else f"{cond} {name}={value}", {})
            for seed in range(args.seeds):
                if cond == "sim":
                    res.outcomes[seed] = s2r.run_sim(policy, train_cfg, seed, args.episodes)
                    bar.update(args.episodes)
                    continue
                which, use_hmd = s2r.CELL_CONDITIONS[cond]
                played = cells[which]
                cfg = s2r.replace_gap(played.env, **{name: value}) if name in GAP_PARAMS else played.env
                res.outcomes[seed] = s2r.run_real(
                    Path(args.policy),
                    cfg,
                    played.bus,
                    seed,
                    args.episodes,
                    out / f"log-{cond}-{name or 'default'}-{value}-seed{seed}-{time.strftime('%H%M%S')}.jsonl",
                    played.path,
                    played.safety,
                    on_episode=lambda o: bar.update(1),
                    use_hmd=use_hmd,
                    hmd_overrides={name: value} if name in HMD_PARAMS else None,
                    recover=not args.no_recovery,
                    condition=cond,
                )
            results.append(res)
    md = s2r.write_report(results, out, s2r.gap_description(real_cfg, real_path))
    print(md.read_text())
    print(f"figure and CSV in {out}")
    return 0


def _check_sweeps(sweeps: list[tuple[str, list[float]]], real_cfg, hmd) -> None:
    """ConfigError (from the config dataclasses' own range checks) for a swept value out of its range."""
    from dataclasses import replace

    from mrguide.config import ConfigError
    from mrguide.experiments import sim2real as s2r

    for name, values in sweeps:
        for value in values:
            try:
                if name in GAP_PARAMS:
                    s2r.replace_gap(real_cfg, **{name: value})
                else:
                    replace(hmd, **{name: value})
            except ConfigError as exc:
                raise ConfigError(f"--sweep {name}={value}: {exc}") from exc
