"""CAN bus benchmark: 6 CiA 402 drives + vacuum generator on python-can's virtual bus, at 250 and 500 Hz.

For each control rate the simulated cobot and the master run in this process while the master streams a
continuous motion on all joints. Reported per rate: achieved SYNC rate, SYNC lateness (jitter) p50/p99/max
against the absolute deadlines, missed cycles, CAN frames/s, the bus load those frames would be at 1 Mbit/s
(worst-case bit stuffing), lost/late feedback and tracking error. Target: 250 Hz with zero missed cycles and
p99 jitter <= 1 ms. The last line is one JSON object with the figures.

    python benchmarks/can_bus.py [--seconds 30] [--realtime-priority 50]
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import platform
import sys
import time
from dataclasses import replace

import numpy as np

from mrguide.drivers import Cobot, CobotBusConfig, CycleSample, DriverError
from mrguide.drivers.config import BusConfig, TimingConfig
from mrguide.drivers.mock import FirstOrderPlant, SimulatedCobot
from mrguide.drivers.realtime import make_current_thread_realtime, settled_heap
from mrguide.drivers.tracking import TrackingRecorder
from mrguide.robot import load_robot

RATES = (250, 500)
#: Motion streamed during the measurement: q_home + A * sin(2 pi t / P) on every joint (0.63 rad/s peak).
AMPLITUDE = 0.2
PERIOD = 2.0
REFERENCE_BITRATE = 1_000_000


def run_rate(rate: int, seconds: float, priority: int) -> dict[str, float]:
    robot = load_robot()
    config = replace(
        CobotBusConfig(),
        bus=BusConfig(channel=f"bench-{rate}"),
        timing=TimingConfig(control_period=1.0 / rate, realtime_priority=priority, setpoint_queue_depth=8),
    )
    lateness: list[float] = []
    tracking = TrackingRecorder(robot.dof)

    def observe(sample: CycleSample) -> None:
        lateness.append(sample.lateness)
        tracking(sample)

    with settled_heap(), SimulatedCobot(config, FirstOrderPlant(robot.q_home)) as sim, Cobot(config, robot) as cobot:
        cobot.enable()
        q0 = cobot.setpoint
        before = cobot.stats()
        cobot.add_cycle_observer(observe)
        start = time.monotonic()
        k = 0
        while time.monotonic() - start < seconds:
            k += 1
            cobot.stream(q0 + AMPLITUDE * np.sin(2 * np.pi * k * cobot.period / PERIOD))
        elapsed = time.monotonic() - start
        cobot.remove_cycle_observer(observe)
        after = cobot.stats()
        sim_syncs = sim.stats().syncs
    lat = np.array(lateness) * 1e3
    cycles = after.cycles - before.cycles
    bits = after.bits_tx + after.bits_rx - before.bits_tx - before.bits_rx
    return {
        "rate_hz": cycles / elapsed,
        "jitter_p50_ms": float(np.percentile(lat, 50)),
        "jitter_p99_ms": float(np.percentile(lat, 99)),
        "jitter_max_ms": float(lat.max()),
        "missed_cycles": after.missed_cycles - before.missed_cycles,
        "frames_per_s": (after.frames_tx + after.frames_rx - before.frames_tx - before.frames_rx) / elapsed,
        "bus_load": bits / elapsed / REFERENCE_BITRATE,
        "lost_feedback": after.lost_feedback - before.lost_feedback,
        "underruns": after.underruns - before.underruns,
        "tracking_max_mrad": float(tracking.max_error.max() * 1e3),
        "sim_syncs": sim_syncs,
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=30.0, help="measurement time per rate (default 30)")
    parser.add_argument(
        "--realtime-priority",
        type=int,
        default=50,
        help="SCHED_FIFO priority for the whole process, 0 = normal scheduling (default 50)",
    )
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    realtime = args.realtime_priority > 0 and make_current_thread_realtime(args.realtime_priority)
    scheduling = f"SCHED_FIFO {args.realtime_priority}" if realtime else "normal (SCHED_OTHER)"
    print(f"CAN bus benchmark: 6 CiA 402 drives + vacuum generator, virtual bus, {args.seconds:g} s per rate")
    print(
        f"machine: {platform.node()} {platform.machine()}, {os.cpu_count()} cores, "
        f"load average {os.getloadavg()[0]:.2f}, python {platform.python_version()}, scheduling {scheduling}"
    )
    try:
        results = {rate: run_rate(rate, args.seconds, args.realtime_priority if realtime else 0) for rate in RATES}
    except DriverError as exc:
        print(f"benchmark aborted: {type(exc).__name__}: {exc}", file=sys.stderr)
        return 1

    rows = [
        ("achieved SYNC rate (Hz)", "rate_hz", "{:.2f}"),
        ("jitter p50 (ms)", "jitter_p50_ms", "{:.3f}"),
        ("jitter p99 (ms)", "jitter_p99_ms", "{:.3f}"),
        ("jitter max (ms)", "jitter_max_ms", "{:.3f}"),
        ("missed cycles", "missed_cycles", "{:d}"),
        ("frames/s", "frames_per_s", "{:.0f}"),
        ("bus load at 1 Mbit/s", "bus_load", "{:.1%}"),
        ("lost/late TPDOs", "lost_feedback", "{:d}"),
        ("setpoint underruns", "underruns", "{:d}"),
        ("max tracking error (mrad)", "tracking_max_mrad", "{:.2f}"),
    ]
    print(f"\n{'':28s}" + "".join(f"{f'{r} Hz':>12s}" for r in RATES))
    for label, key, fmt in rows:
        print(f"{label:28s}" + "".join(f"{fmt.format(results[r][key]):>12s}" for r in RATES))
    target_met = results[250]["missed_cycles"] == 0 and results[250]["jitter_p99_ms"] <= 1.0
    print(f"\n250 Hz target (0 missed cycles, p99 jitter <= 1 ms): {'met' if target_met else 'NOT met'}")
    print("jitter = SYNC transmission time minus its absolute deadline; bus load from worst-case frame bit lengths")

    figures: dict[str, object] = {"seconds": args.seconds, "scheduling": scheduling, "cores": os.cpu_count()}
    for rate, res in results.items():
        for key, value in res.items():
            figures[f"{key}_{rate}"] = round(value, 4) if isinstance(value, float) else value
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    sys.exit(main())
