"""`mrguide sim2real`: argument parsing, progress and the sweep over reality-gap / HMD-noise parameters."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from tqdm import tqdm

GAP_PARAMS = ("object_mass", "object_friction", "suction_break_force", "actuator_latency", "actuator_lag", "joint_noise", "vacuum_noise")
HMD_PARAMS = ("tracking_noise_m", "tracking_noise_deg", "calibration_error_m", "calibration_error_deg")


def add_sim2real_command(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("sim2real", help="the three sim-to-real conditions of the paper (Fig. 8) for one policy")
    p.add_argument("--policy", required=True)
    p.add_argument("--config", default=None, help="TOML of the training twin (condition 1); default: built-in defaults")
    p.add_argument("--real-config", default="configs/real_cell.toml",
                   help="TOML of the 'real' cell: [twin.reality_gap], [deploy] bus_config, [calibration.hmd] (conditions 2, 3)")
    p.add_argument("--seeds", type=int, default=3)
    p.add_argument("--episodes", type=int, default=10, help="episodes per seed and condition")
    p.add_argument("--conditions", default=",".join(("sim", "real_exact", "real_hmd")))
    p.add_argument("--sweep", action="append", default=[], metavar="PARAM=v1,v2,...",
                   help=f"instead of the three conditions, success vs one parameter; reality gap ({', '.join(GAP_PARAMS)}) "
                        f"runs condition 2, HMD ({', '.join(HMD_PARAMS)}) condition 3; repeatable")
    p.add_argument("--no-recovery", action="store_true",
                   help="a safety stop ends the seed's run (its remaining episodes fail); default: fault reset, "
                        "the stopped episode fails, the next one runs")
    p.add_argument("--out", default="runs/sim2real")
    p.add_argument("--quiet", action="store_true")
    p.set_defaults(func=cmd_sim2real)


def cmd_sim2real(args: argparse.Namespace) -> int:
    from mrguide.config import ConfigError, load_optional_section, load_section
    from mrguide.deploy.policy import ExportedPolicy, PolicyFileError
    from mrguide.deploy.safety import SafetyConfig
    from mrguide.deploy.session import DeployConfig
    from mrguide.drivers.config import load_cobot_bus_config
    from mrguide.robot import load_robot
    from mrguide.twin import sim2real as s2r
    from mrguide.twin.env import EnvConfig

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    train_cfg = EnvConfig.load(args.config)
    real_path = Path(args.real_config)
    real_cfg = EnvConfig.load(real_path)
    dcfg = load_section(DeployConfig, real_path, "deploy")
    bus = load_cobot_bus_config(real_path.parent / dcfg.bus_config if dcfg.bus_config else None)
    safety = load_optional_section(SafetyConfig, real_path, "safety")
    try:
        policy = ExportedPolicy.load(args.policy, load_robot(train_cfg.robot).workspace, train_cfg.task)
    except PolicyFileError as exc:
        print(f"mrguide sim2real: {exc}")
        return 2
    conditions = [c.strip() for c in args.conditions.split(",") if c.strip()]
    unknown = [c for c in conditions if c not in s2r.CONDITIONS]
    if unknown:
        raise ConfigError(f"--conditions: unknown {unknown}; known: {', '.join(s2r.CONDITIONS)}")
    sweeps = [_parse_sweep(s) for s in args.sweep]
    runs = [(c, None, None) for c in conditions] if not sweeps else [
        ("real_hmd" if name in HMD_PARAMS else "real_exact", name, v) for name, values in sweeps for v in values]
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
                cfg = s2r.replace_gap(real_cfg, **{name: type(getattr(real_cfg.twin.reality_gap, name))(value)}) if name in GAP_PARAMS else real_cfg
                res.outcomes[seed] = s2r.run_real(
                    Path(args.policy), cfg, bus, seed, args.episodes,
                    out / f"log-{cond}-{name or 'default'}-{value}-seed{seed}-{time.strftime('%H%M%S')}.jsonl",
                    real_path, safety, on_episode=lambda o: bar.update(1), use_hmd=cond == "real_hmd",
                    hmd_overrides={name: value} if name in HMD_PARAMS else None, recover=not args.no_recovery)
            results.append(res)
    md = s2r.write_report(results, out, s2r.gap_description(real_cfg, real_path))
    print(md.read_text())
    print(f"figure and CSV in {out}")
    return 0


def _parse_sweep(text: str) -> tuple[str, list[float]]:
    from mrguide.config import ConfigError

    name, _, values = text.partition("=")
    if name not in GAP_PARAMS + HMD_PARAMS or not values:
        raise ConfigError(f"--sweep {text!r}: expected PARAM=v1,v2,... with PARAM one of {', '.join(GAP_PARAMS + HMD_PARAMS)}")
    try:
        return name, [float(v) for v in values.split(",")]
    except ValueError as exc:
        raise ConfigError(f"--sweep {text!r}: values must be numbers") from exc
