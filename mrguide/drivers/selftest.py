"""Bus self-test: boot the cobot, enable it, move each joint a little and back, toggle the vacuum, report.

On the `virtual` interface the simulated devices (first-order plant) are started on the same channel;
on any other interface the real cobot is used and really moves.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import numpy as np

from mrguide.drivers.cobot import Cobot
from mrguide.drivers.config import CobotBusConfig
from mrguide.drivers.mock.first_order_plant import FirstOrderPlant
from mrguide.drivers.mock.sim_cobot import SimulatedCobot, shared_pc_config
from mrguide.drivers.realtime import settled_heap
from mrguide.drivers.tracking import TrackingRecorder
from mrguide.motion.trajectory import point_to_point
from mrguide.robot import RobotSpec

#: How far each joint moves (rad) and the pass criteria (rad).
MOVE = 0.05
MAX_TRACKING_ERROR = 0.01
MAX_FINAL_ERROR = 1e-3
#: Settling time after each move before the final error is read (s).
SETTLE = 0.1
#: On real hardware without a part, vacuum on must at least raise the level this much (kPa).
OPEN_CUP_MIN_KPA = 1.0


def run_selftest(config: CobotBusConfig, robot: RobotSpec, write: Callable[[str], None]) -> bool:
    """Run the self-test, writing a report line by line; True if every check passed. The heap is settled while the
    bus runs (`settled_heap`), as in a deploy: no full garbage collection pauses the control cycle."""
    with settled_heap():
        return _selftest(config, robot, write)


def _selftest(config: CobotBusConfig, robot: RobotSpec, write: Callable[[str], None]) -> bool:
    bus = config.bus
    simulate = bus.interface == "virtual"
    if simulate:
        config = shared_pc_config(config)
    write(
        f"mrguide bus selftest on {bus.interface}:{bus.channel} at {bus.bitrate // 1000} kbit/s, "
        f"control period {config.timing.control_period * 1000:g} ms"
    )
    sim, plant = None, None
    if simulate:
        plant = FirstOrderPlant(robot.q_home)
        sim = SimulatedCobot(config, plant)
        sim.start()
        write(
            f"  simulated devices: drives {[j.node_id for j in config.joints]}, vacuum generator "
            f"{config.vacuum.node_id}, first-order plant"
        )
    cobot = Cobot(config, robot)
    passed = True
    try:
        t0 = time.monotonic()
        cobot.connect()
        write(f"  boot, SDO configuration, NMT start    {time.monotonic() - t0:6.2f} s   OK")
        t0 = time.monotonic()
        cobot.enable()
        write(f"  enable (OPERATION ENABLED, CSP)       {time.monotonic() - t0:6.2f} s   OK")
        recorder = TrackingRecorder(robot.dof)
        cobot.add_cycle_observer(recorder)
        for i, (name, joint) in enumerate(zip(robot.joint_names, config.joints)):
            passed &= _move_joint(cobot, robot, recorder, i, f"{name} (node {joint.node_id})", write)
        passed &= _toggle_vacuum(cobot, plant, write)
        stats = cobot.stats()
        write(
            f"  cycles {stats.cycles}, missed {stats.missed_cycles}, SYNC lateness p50/p99/max "
            f"{stats.lateness_p50 * 1e3:.2f}/{stats.lateness_p99 * 1e3:.2f}/{stats.lateness_max * 1e3:.2f} ms, "
            f"work p99/max {stats.work_p99 * 1e3:.2f}/{stats.work_max * 1e3:.2f} ms "
            f"({stats.work_overruns} past the period), "
            f"lost feedback {stats.lost_feedback}, frames tx/rx {stats.frames_tx}/{stats.frames_rx}"
        )
    finally:
        cobot.disconnect()
        if sim is not None:
            sim.stop()
    write(f"RESULT: {'PASS' if passed else 'FAIL'}")
    return passed


def _move_joint(
    cobot: Cobot, robot: RobotSpec, recorder: TrackingRecorder, i: int, label: str, write: Callable[[str], None]
) -> bool:
    start = cobot.setpoint
    step = MOVE if start[i] + MOVE <= cobot.limits.q_upper[i] else -MOVE
    goal = start.copy()
    goal[i] += step
    recorder.reset()
    for q_from, q_to in ((start, goal), (goal, start)):
        for q in point_to_point(robot, q_from, q_to, cobot.period):
            cobot.stream(q)
        time.sleep(SETTLE)
    final = float(np.max(np.abs(cobot.joint_state().positions - start)))
    worst = float(recorder.max_error.max())
    ok = worst <= MAX_TRACKING_ERROR and final <= MAX_FINAL_ERROR
    write(
        f"  {label:32s} {step:+.3f} rad and back: max tracking error {worst:.4f} rad, "
        f"final error {final:.5f} rad   {'OK' if ok else 'FAIL'}"
    )
    return ok


def _toggle_vacuum(cobot: Cobot, plant: FirstOrderPlant | None, write: Callable[[str], None]) -> bool:
    if plant is not None:
        plant.place_part()
    cobot.set_vacuum(True)
    time.sleep(0.5)
    on = cobot.vacuum_state()
    cobot.set_vacuum(False, blow_off=True)
    time.sleep(0.3)
    cobot.set_vacuum(False)
    off = cobot.vacuum_state()
    if plant is not None:
        ok = on.part_gripped and not off.part_gripped and not plant.part_present()
        detail = (
            f"part gripped: {on.part_gripped}; after blow-off {off.level_kpa:.1f} kPa, part released: "
            f"{not plant.part_present()}"
        )
    else:
        ok = on.level_kpa >= OPEN_CUP_MIN_KPA
        detail = f"part gripped: {on.part_gripped} (no part expected); after blow-off {off.level_kpa:.1f} kPa"
    write(f"  vacuum on: {on.level_kpa:.1f} kPa, {detail}   {'OK' if ok else 'FAIL'}")
    return ok
