"""Deploy benchmark: decision latency, policy inference time and control-cycle jitter during a dry run.

Run: python benchmarks/deploy.py [--episodes N] [--robot ur10] [--cell configs/cells/mujoco_cell.toml]. The dry
run drives the scripted expert through the whole stack (IK, Ruckig, CANopen over the virtual bus, simulated drives,
the cell of --cell with the chosen arm: default the "real" twin of configs/cells/real_cell.toml and the UR5); inference is timed on an exported actor of the
default size. Prints a table; the last line is one JSON object.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from mrguide.cell.config import CellConfig
from mrguide.cell.dry_run import dry_run
from mrguide.cli_args import positive_int
from mrguide.deploy.policy import ExportedPolicy
from mrguide.deploy.runlog import RunLog
from mrguide.drivers.config import load_cobot_bus_config
from mrguide.robot import load_robot
from mrguide.task import oracle_action


def bench_inference(n: int = 20000) -> tuple[float, str]:
    """Median time of one forward pass of an exported default-size actor, and its hidden layout."""
    from mrguide.policies.ddpg import DDPG, DDPGConfig
    from mrguide.policies.export import export_actor
    from mrguide.policies.networks import obs_scaling
    from mrguide.task import TaskConfig

    spec = load_robot()
    with tempfile.TemporaryDirectory() as tmp:
        cfg = DDPGConfig()
        path = export_actor(
            DDPG(*obs_scaling(spec.workspace), 4, cfg).actor, Path(tmp) / "p.npz", spec, TaskConfig(), 0.1
        )
        pol = ExportedPolicy.load(path)
    obs = np.zeros(11, np.float32)
    times = []
    for _ in range(n):
        t = time.perf_counter()
        pol(obs)
        times.append(time.perf_counter() - t)
    return float(np.median(times) * 1e3), "x".join(map(str, cfg.hidden))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--episodes", type=positive_int, default=10)
    ap.add_argument("--robot", default="", help="a shipped arm (ur5, ur10) in place of the real cell's (the UR5)")
    ap.add_argument(
        "--cell",
        type=Path,
        default=Path(__file__).parents[1] / "configs" / "cells" / "real_cell.toml",
        help="the cell's TOML ([plant] engine: the PyBullet twin or the MuJoCo cell)",
    )
    args = ap.parse_args()
    cfg = CellConfig.load(args.cell)
    if args.robot:
        cfg = cfg.with_value("robot.name", args.robot, "--robot")
    spec = load_robot(cfg.robot)
    ws = spec.workspace
    with tempfile.TemporaryDirectory() as tmp, RunLog(Path(tmp) / "log.jsonl", {"benchmark": "deploy"}) as run_log:
        summary = dry_run(
            None,
            cfg,
            load_cobot_bus_config(None, spec),
            args.episodes,
            0,
            run_log,
            policy=lambda obs: oracle_action(obs, cfg.task, ws.to_normalized),
        )
    lat = summary.latency_ms()
    inference_ms, hidden = bench_inference()
    res = {
        "robot": spec.name,
        "engine": cfg.plant.engine,
        "decision_latency_p50_ms": float(np.percentile(lat, 50)),
        "decision_latency_p99_ms": float(np.percentile(lat, 99)),
        "policy_inference_ms": inference_ms,
        "cycle_jitter_p99_ms": summary.cycle_lateness_p99_ms,
        "cycle_work_p99_ms": summary.cycle_work_p99_ms,
        "cycle_work_max_ms": summary.cycle_work_max_ms,
        "missed_cycles": summary.missed_cycles,
        "dry_run_success": summary.successes / max(len(summary.episodes), 1),
        "episodes": len(summary.episodes),
    }
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; arm {spec.name}, "
        f"cell {args.cell.name} ({cfg.plant.engine})"
    )
    for name, key, target in (
        ("decision latency p50 (state read -> first setpoint)", "decision_latency_p50_ms", ""),
        ("decision latency p99", "decision_latency_p99_ms", "<= 5 ms"),
        (f"policy inference ({hidden} MLP, numpy)", "policy_inference_ms", "<= 0.1 ms"),
        ("control-cycle lateness p99 (SYNC vs deadline)", "cycle_jitter_p99_ms", ""),
        ("control-cycle work p99 (start to end of observers)", "cycle_work_p99_ms", ""),
        ("control-cycle work max", "cycle_work_max_ms", "< 4 ms period"),
    ):
        print(f"{name:<55} {res[key]:8.3f} ms  {target}")
    print(
        f"missed cycles {res['missed_cycles']}, dry-run success {res['dry_run_success']:.0%} over {res['episodes']} episodes"
        + (f", stopped: {summary.stopped}" if summary.stopped else "")
    )
    print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in res.items()}))


if __name__ == "__main__":
    main()
