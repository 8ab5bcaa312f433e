"""Frame-loss benchmark: spurious quick stops under random CAN frame loss, and fault-detection times.

Uses the timing of a bus config (default `configs/devices/cobot_bus.toml`, the real timing: no test leniency) with
the simulated cobot (first-order plant) and the master in this process, on a private virtual channel.

1. Frame loss: `--runs` runs of `--seconds` each. The master enables the drives and streams a slow sine on
   every joint while the simulated devices lose every frame they send or receive (SYNC, PDOs, heartbeats of
   both directions, SDO, EMCY) with probability `--loss`. Counted: runs that end in a latched fault
   (quick stop), by kind, and when.
2. Detection, no loss, `--repeats` times each: a drive falls silent (all frames: missing TPDOs and the
   master's heartbeat consumer), a drive's heartbeat alone stops (heartbeat consumer), and the master's
   control thread hangs (every device's consumer of the master heartbeat; time until all drives are
   disabled and every device left OPERATIONAL).

    python benchmarks/frame_loss.py [--config configs/devices/cobot_bus.toml] [--runs 20] [--seconds 5] [--loss 0.05]
                                    [--repeats 5] [--realtime-priority 0]

The last line is one JSON object with the figures.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import sys
import threading
import time
import uuid
from collections import Counter
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np

from mrguide.drivers import Cobot, CobotBusConfig, DriverError, load_cobot_bus_config
from mrguide.drivers.mock import FirstOrderPlant, SimulatedCobot
from mrguide.drivers.mock.drive_sim import OPERATION_ENABLED
from mrguide.drivers.realtime import make_current_thread_realtime, settled_heap
from mrguide.robot import RobotSpec, load_robot

REPO_CONFIG = Path(__file__).resolve().parents[1] / "configs" / "devices" / "cobot_bus.toml"
#: Streamed motion: q_home + A sin(2 pi t / P) on every joint (0.31 rad/s peak).
AMPLITUDE = 0.1
PERIOD = 2.0
SILENT_NODE = 5
#: Longest wait for a detection before it counts as missed (s).
DETECTION_LIMIT = 5.0


def _private(config: CobotBusConfig) -> CobotBusConfig:
    return replace(config, bus=replace(config.bus, interface="virtual", channel=f"loss-{uuid.uuid4().hex[:10]}"))


def loss_run(
    config: CobotBusConfig, robot: RobotSpec, loss: float, seconds: float, seed: int
) -> tuple[str, float, str] | None:
    """One run with frame loss: None if it lasted, else (fault kind, seconds into the loss, message)."""
    config = _private(config)
    with SimulatedCobot(config, FirstOrderPlant(robot.q_home), seed=seed) as sim, Cobot(config, robot) as cobot:
        cobot.enable()
        q0 = cobot.setpoint
        sim.faults.set_drop_rate(loss)
        start, k = time.monotonic(), 0
        try:
            while time.monotonic() - start < seconds:
                k += 1
                cobot.stream(q0 + AMPLITUDE * np.sin(2 * np.pi * k * cobot.period / PERIOD))
        except DriverError as exc:
            fault = cobot.status().fault or exc
            fault_at = cobot.status().fault_at or time.monotonic()
            return type(fault).__name__, fault_at - start, str(fault)
        finally:
            sim.faults.set_drop_rate(0.0)
    return None


def _until(predicate: Callable[[], bool], limit: float = DETECTION_LIMIT) -> float:
    """Seconds until `predicate` holds (polled every ms); NaN if it never did within `limit`."""
    start = time.monotonic()
    while not predicate():
        if time.monotonic() - start > limit:
            return float("nan")
        time.sleep(0.001)
    return time.monotonic() - start


def detect_silent_node(config: CobotBusConfig, robot: RobotSpec) -> dict[str, float]:
    """A drive stops sending anything: time to the latched fault (missing TPDOs) and to heartbeat loss."""
    config = _private(config)
    with SimulatedCobot(config, FirstOrderPlant(robot.q_home)) as sim, Cobot(config, robot) as cobot:
        cobot.enable()
        silenced = time.monotonic()
        sim.faults.silence(SILENT_NODE)
        fault = _until(lambda: cobot.status().fault is not None)
        heartbeat = _until(lambda: SILENT_NODE in cobot.status().heartbeat_lost, DETECTION_LIMIT - fault) + fault
        kind = type(cobot.status().fault).__name__
        return {"fault_s": fault, "heartbeat_s": heartbeat, "first_kind": kind, "total_s": time.monotonic() - silenced}


def detect_heartbeat_only(config: CobotBusConfig, robot: RobotSpec) -> dict[str, float]:
    """A drive's heartbeat stops, its PDOs go on: only the master's heartbeat consumer can tell."""
    config = _private(config)
    with SimulatedCobot(config, FirstOrderPlant(robot.q_home)) as sim, Cobot(config, robot) as cobot:
        cobot.enable()
        sim.faults.silence(SILENT_NODE, heartbeat_only=True)
        return {
            "fault_s": _until(lambda: cobot.status().fault is not None),
            "first_kind": type(cobot.status().fault).__name__,
        }


def detect_hung_master(config: CobotBusConfig, robot: RobotSpec) -> dict[str, float]:
    """The master's control thread hangs (no SYNC, no heartbeat): time until the devices disabled themselves."""
    config = _private(config)
    release = threading.Event()
    with SimulatedCobot(config, FirstOrderPlant(robot.q_home)) as sim, Cobot(config, robot) as cobot:
        cobot.enable()
        cycle = cobot._loop.cycle
        cobot._loop.cycle = lambda tick: release.wait()
        try:
            took = _until(
                lambda: (
                    all(d.state != OPERATION_ENABLED for d in sim.drives)
                    and not any(s.operational for s in (*sim.drives, sim.vacuum))
                )
            )
        finally:
            cobot._loop.cycle = cycle
            release.set()
    return {"devices_s": took}


def _stats(values: list[float]) -> tuple[float, float]:
    arr = np.array(values, dtype=float)
    return float(np.nanmedian(arr)), float(np.nanmax(arr))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", type=Path, default=REPO_CONFIG, help="bus config whose timing is used")
    parser.add_argument("--runs", type=int, default=20, help="frame-loss runs (default 20)")
    parser.add_argument("--seconds", type=float, default=5.0, help="length of one frame-loss run (default 5 s)")
    parser.add_argument("--loss", type=float, default=0.05, help="probability of losing each frame (default 0.05)")
    parser.add_argument("--repeats", type=int, default=5, help="repeats of each detection measurement (default 5)")
    parser.add_argument(
        "--realtime-priority",
        type=int,
        default=50,
        help="SCHED_FIFO priority of the whole process (master and simulated devices, which stand "
        "for hardware with its own timing), as on the robot PC; 0 = normal scheduling (default 50)",
    )
    args = parser.parse_args()
    if args.runs < 1 or args.repeats < 1 or not args.seconds > 0 or not 0 <= args.loss < 1:
        parser.error("--runs and --repeats must be >= 1, --seconds > 0, --loss in [0, 1)")
    logging.basicConfig(level=logging.CRITICAL)  # the faults are provoked: the table reports them
    config = load_cobot_bus_config(args.config)
    realtime = args.realtime_priority > 0 and make_current_thread_realtime(args.realtime_priority)
    config = replace(config, timing=replace(config.timing, realtime_priority=args.realtime_priority if realtime else 0))
    robot = load_robot()
    with settled_heap():
        return _run(args, config, robot)


def _print_header(args: argparse.Namespace, t) -> None:
    """The bus timing under test and the machine."""
    print(
        f"frame-loss benchmark, timing of {args.config}: {t.control_period * 1e3:g} ms cycle, heartbeats every "
        f"{t.heartbeat_ms} ms, consumer time {t.heartbeat_timeout_ms} ms (x{t.heartbeat_timeout_factor:g}), "
        f"feedback lost after {t.max_missed_feedback} cycles, SCHED_FIFO {t.realtime_priority or 'off'}"
    )
    print(
        f"machine: {platform.node()} {platform.machine()}, {os.cpu_count()} cores, "
        f"load average {os.getloadavg()[0]:.2f}, python {platform.python_version()}"
    )


def _run(args: argparse.Namespace, config, robot) -> int:
    t = config.timing
    _print_header(args, t)
    outcomes = [loss_run(config, robot, args.loss, args.seconds, seed) for seed in range(args.runs)]
    faults = [o for o in outcomes if o is not None]
    kinds = Counter(kind for kind, _, _ in faults)
    print(
        f"\n{args.loss:.0%} frame loss, {args.runs} runs of {args.seconds:g} s: {len(faults)} quick stops"
        + (f" {dict(kinds)}" if faults else "")
    )
    for kind, at, message in faults:
        print(f"  after {at:5.2f} s: {kind}: {message[:110]}")

    silent = [detect_silent_node(config, robot) for _ in range(args.repeats)]
    hb_only = [detect_heartbeat_only(config, robot) for _ in range(args.repeats)]
    hung = [detect_hung_master(config, robot) for _ in range(args.repeats)]
    rows = [
        (
            "silent drive -> latched fault",
            _stats([r["fault_s"] for r in silent]),
            Counter(r["first_kind"] for r in silent),
        ),
        ("silent drive -> heartbeat lost", _stats([r["heartbeat_s"] for r in silent]), None),
        (
            "drive heartbeat stops -> fault",
            _stats([r["fault_s"] for r in hb_only]),
            Counter(r["first_kind"] for r in hb_only),
        ),
        ("master hangs -> devices disabled", _stats([r["devices_s"] for r in hung]), None),
    ]
    print(f"\ndetection without loss, {args.repeats} repeats    median ms     max ms   detected by")
    for label, (median, worst), by in rows:
        print(f"{label:40s}{median * 1e3:10.1f}{worst * 1e3:11.1f}   {dict(by) if by else ''}")

    figures = {
        "config": str(args.config),
        "loss": args.loss,
        "runs": args.runs,
        "seconds": args.seconds,
        "heartbeat_ms": t.heartbeat_ms,
        "consumer_ms": t.heartbeat_timeout_ms,
        "max_missed_feedback": t.max_missed_feedback,
        "realtime_priority": t.realtime_priority,
        "quick_stops": len(faults),
        "quick_stop_kinds": dict(kinds),
        "load_average": os.getloadavg()[0],
    }
    for (_, (median, worst), _), key in zip(
        rows, ("silent_fault", "silent_heartbeat", "heartbeat_only", "hung_master")
    ):
        figures[f"{key}_median_ms"], figures[f"{key}_max_ms"] = round(median * 1e3, 1), round(worst * 1e3, 1)
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
