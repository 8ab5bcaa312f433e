"""`mrguide sim2real`: the sim-to-real conditions (Fig. 8) for one policy, or its success against one reality-gap or
HMD parameter (`--sweep`). Every input is checked before the first episode; PyBullet is imported only to run."""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

from tqdm import tqdm

from mrguide.cli_args import add_set_argument, positive_int
from mrguide.config import ConfigError
from mrguide.experiments.sim2real_runs import CONDITIONS
from mrguide.shipped_configs import shipped_config

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
HMD_PARAMS = (
    "tracking_noise_m",
    "tracking_noise_deg",
    "calibration_error_m",
    "calibration_error_deg",
    "latency_s",
    "frame_drop",
)


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
    add_set_argument(
        p,
        "set a key of the played cells (the 'real' one and the MuJoCo one) for this run, after their files "
        "(e.g. --set twin.reality_gap.object_mass=0.4 --set calibration.hmd.tracking_noise_m=0.005); repeatable; "
        "sections: twin, task, robot, plant, safety, calibration.hmd",
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


#: The sections of the played cell that `mrguide sim2real --set` sets: its env config's, its safety, its HMD.
ENV_SECTIONS = ("twin", "task", "robot", "plant")
CELL_SET_SECTIONS = (*ENV_SECTIONS, "safety", "calibration.hmd")


def set_cell_keys(cell: Any, sets: list[tuple[str, Any]]) -> Any:
    """The played cell (`sim2real.RealCell`) with each (dotted key, value) of `--set` applied, checked as a value in
    its file would be."""
    from dataclasses import replace

    from mrguide.config import replace_path
    from mrguide.deploy.safety import SafetyConfig

    for key, value in sets:
        where = f"--set {key}"
        if key.split(".", 1)[0] in ENV_SECTIONS:
            cell = replace(cell, env=cell.env.with_value(key, value, where))
        elif key.startswith("safety."):
            safety = cell.safety or SafetyConfig()
            cell = replace(cell, safety=replace_path(safety, key.removeprefix("safety."), value, where))
        elif key.startswith("calibration.hmd."):
            cell = replace(cell, hmd=replace_path(cell.hmd, key.removeprefix("calibration.hmd."), value, where))
        else:
            raise ConfigError(f"{where}: sim2real sets keys of the played cell's {', '.join(CELL_SET_SECTIONS)}")
    return cell


def cmd_sim2real(args: argparse.Namespace) -> int:
    """Every input is checked before the first episode: configs, bus, policy (against both twins), swept values,
    the output directory."""
    from mrguide.experiments import sim2real as s2r
    from mrguide.experiments.sim2real_report import cells_description, write_report
    from mrguide.output_files import check_output_dir
    from mrguide.twin.env import EnvConfig

    out = check_output_dir(args.out, "--out")
    train_cfg = EnvConfig.load(args.config)
    cell = set_cell_keys(s2r.load_real_cell(args.real_config or shipped_config("cells", "real_cell.toml")), args.set)
    cells = {"real": cell}
    if {"mujoco_exact", "mujoco_hmd"} & set(args.conditions):
        mujoco = s2r.load_real_cell(args.mujoco_config or shipped_config("cells", "mujoco_cell.toml"))
        cells["mujoco"] = set_cell_keys(mujoco, args.set)
    real_cfg, hmd = cell.env, cell.hmd
    hmd_sets = {key.removeprefix("calibration.hmd."): v for key, v in args.set if key.startswith("calibration.hmd.")}
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
    results = _play(args, runs, cells, train_cfg, policy, hmd_sets, out)
    md = write_report(results, out, cells_description(cells, [c for c, _, _ in runs]))
    print(md.read_text())
    print(f"figure and CSV in {out}")
    return 0


def _play(args: argparse.Namespace, runs: list, cells: dict, train_cfg: Any, policy: Any, hmd_sets: dict, out: Path):
    """Every (condition, swept parameter, value) of `runs` for each seed: the conditions' results, in order."""
    from mrguide.experiments import sim2real as s2r

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
                    hmd_overrides={**hmd_sets, **({name: value} if name in HMD_PARAMS else {})} or None,
                    condition=cond,
                )
            results.append(res)
    return results


def _check_sweeps(sweeps: list[tuple[str, list[float]]], real_cfg, hmd) -> None:
    """ConfigError (from the config dataclasses' own range checks) for a swept value out of its range."""
    from dataclasses import replace

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
