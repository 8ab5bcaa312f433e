"""Twin benchmark: env decisions/s, sim-to-wall factor, oracle success, a scene's start, IK and Ruckig timing.

Run: python benchmarks/twin.py [--episodes N] [--config C]. The arm is the config's ([robot], default UR5;
e.g. --config configs/runs/ur10_run.toml). Oracle episodes use env seeds 0..N-1. Prints a table; the last line is
one JSON object.
"""

from __future__ import annotations

import argparse
import itertools
import json
import os
import platform
import time

import numpy as np

from mrguide.motion.kinematics import IKError, Kinematics
from mrguide.motion.trajectory import JointStreamer
from mrguide.robot import RobotSpec, load_robot
from mrguide.twin.env import EnvConfig, PickPlaceEnv
from mrguide.twin.rollout import run_episodes


def bench_env(episodes: int, cfg: EnvConfig) -> dict:
    env = PickPlaceEnv(cfg)
    try:
        run_episodes(env, lambda o: env.expert_action(), range(3))  # warm-up
        s = run_episodes(env, lambda o: env.expert_action(), range(episodes))
    finally:
        env.close()
    rate = s.decisions / s.wall_s
    return {
        "decisions_per_s": rate,
        "sim_to_wall": rate * env.twin_cfg.decision_period,
        "oracle_success": s.success_rate,
        "episodes": episodes,
    }


def bench_scene_start(cfg: EnvConfig, n: int = 7) -> dict:
    """Median seconds to build the env with the arm's visual meshes (a rendering env) and without (every other)."""
    times: dict[str, list[float]] = {"drawn": [], "blind": []}
    for _ in range(n):  # interleaved, so that a busy moment of the machine falls on both
        for kind, mode in (("drawn", "rgb_array"), ("blind", None)):
            t = time.perf_counter()
            env = PickPlaceEnv(cfg, render_mode=mode)
            times[kind].append(time.perf_counter() - t)
            env.close()
    drawn, blind = float(np.median(times["drawn"])), float(np.median(times["blind"]))
    return {"scene_start_drawn_s": drawn, "scene_start_blind_s": blind, "scene_start_ratio": drawn / blind}


def bench_ik(spec: RobotSpec, n: int = 3000) -> dict:
    kin = Kinematics(spec)
    ws = spec.workspace
    rng = np.random.default_rng(0)
    q = spec.q_home.copy()
    p = kin.tcp_position(q)
    times = []
    for _ in range(n):  # warm-started, as in the env and the deploy loop: the next target within 5 cm
        p = np.clip(p + rng.normal(0, 0.03, 3), ws.lo, ws.hi)
        t = time.perf_counter()
        q = kin.ik(p, q)
        times.append(time.perf_counter() - t)
    ms = np.array(times) * 1e3
    return {"ik_median_ms": float(np.median(ms)), "ik_p99_ms": float(np.percentile(ms, 99))}


def bench_ik_round_trips(spec: RobotSpec, n: int = 500, grid: int = 7) -> dict:
    """FK -> IK (seeded at home) -> FK on random configurations near home: worst TCP error; and IK failures on a
    grid x grid x grid lattice of the workspace box with the TCP pointing down."""
    kin = Kinematics(spec)
    rng = np.random.default_rng(2)
    worst = 0.0
    for _ in range(n):
        q = np.clip(spec.q_home + rng.normal(0, 0.3, spec.dof), spec.q_lower, spec.q_upper)
        T = kin.fk(q)
        worst = max(worst, float(np.linalg.norm(kin.fk(kin.ik(T[:3, 3], spec.q_home, T[:3, :3]))[:3, 3] - T[:3, 3])))
    ws, failures = spec.workspace, 0
    for p in itertools.product(*[np.linspace(lo, hi, grid) for lo, hi in zip(ws.lo, ws.hi)]):
        try:
            kin.ik(np.array(p), spec.q_home)
        except IKError:
            failures += 1
    return {
        "ik_round_trip_max_mm": worst * 1e3,
        "ik_round_trips": n,
        "box_ik_failures": failures,
        "box_points": grid**3,
    }


def bench_ruckig(spec: RobotSpec, n: int = 20000) -> dict:
    s = JointStreamer(spec, 0.004)
    rng = np.random.default_rng(1)
    times = []
    for k in range(n):
        if k % 100 == 0:
            s.set_target(rng.uniform(spec.q_lower + 0.2, spec.q_upper - 0.2))
        t = time.perf_counter()
        s.step()
        times.append(time.perf_counter() - t)
    us = np.array(times) * 1e6
    return {"ruckig_cycle_us": float(np.median(us)), "ruckig_cycle_p99_us": float(np.percentile(us, 99))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--episodes", type=int, default=200)
    ap.add_argument("--config", default=None, help="run config TOML ([robot], [twin], [task]); default: built-in (UR5)")
    args = ap.parse_args()
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})  # one core
    cfg = EnvConfig.load(args.config)
    spec = load_robot(cfg.robot)
    res = {
        "robot": spec.name,
        **bench_env(args.episodes, cfg),
        **bench_scene_start(cfg),
        **bench_ik(spec),
        **bench_ik_round_trips(spec),
        **bench_ruckig(spec),
    }
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, pinned to one core;"
        f" arm {spec.name}"
    )
    rows = [
        ("env decisions/s (0.1 s decision, 4 ms control)", f"{res['decisions_per_s']:.0f}", ">= 200"),
        ("simulated / wall time", f"{res['sim_to_wall']:.1f}x", ""),
        (f"oracle success ({res['episodes']} seeded episodes)", f"{res['oracle_success']:.1%}", ">= 98 %"),
        (
            "env start, drawn / blind (median of 7)",
            f"{res['scene_start_drawn_s']:.3f} / {res['scene_start_blind_s']:.3f} s",
            "",
        ),
        ("IK solve median (warm start)", f"{res['ik_median_ms']:.3f} ms", "<= 0.3 ms"),
        ("IK solve p99", f"{res['ik_p99_ms']:.3f} ms", ""),
        (f"IK round trip, worst of {res['ik_round_trips']}", f"{res['ik_round_trip_max_mm']:.4f} mm", "<= 1 mm"),
        ("workspace lattice points out of IK reach", f"{res['box_ik_failures']} of {res['box_points']}", "0"),
        ("Ruckig cycle median / p99", f"{res['ruckig_cycle_us']:.1f} / {res['ruckig_cycle_p99_us']:.1f} us", ""),
    ]
    for name, val, target in rows:
        print(f"{name:<50} {val:>16}  {target}")
    print(json.dumps({k: round(v, 4) if isinstance(v, float) else v for k, v in res.items()}))


if __name__ == "__main__":
    main()
