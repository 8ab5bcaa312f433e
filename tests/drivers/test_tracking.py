"""CSP tracking of a Ruckig trajectory, without and with 5 % random frame loss."""

from __future__ import annotations

import time

import numpy as np

from mrguide.drivers.tracking import TrackingRecorder
from mrguide.motion.trajectory import point_to_point

#: With 5 % loss an RPDO or SYNC may be lost, adding up to one more step (v_max * T = 6-8 mrad).
LOSSY_TRACKING_TOLERANCE = 0.025
FINAL_TOLERANCE = 1e-4
MOVE = np.array([0.8, -0.3, 0.35, 0.4, -0.4, 0.8])


def _run_trajectory(rig, robot):
    """Stream a near-v_max move; (recorder, final error, path, backlog): the backlog is how far the simulated
    devices fell behind the clock meanwhile (s, `SyncBacklog`), on a busy machine. A reply handled that late may be
    taken for the answer to a later SYNC, its error then larger by what the joint moved in between."""
    cobot = rig.cobot
    rig.sim.backlog.take()
    recorder = TrackingRecorder(robot.dof)
    cobot.add_cycle_observer(recorder)
    start = cobot.setpoint
    path = point_to_point(robot, start, start + MOVE, cobot.period)
    peak_speed = np.max(np.abs(np.diff(path, axis=0)), axis=0) / cobot.period
    assert np.any(peak_speed > 0.9 * robot.v_max)  # the test really drives near the velocity limit
    for q in path:
        cobot.stream(q)
    time.sleep(0.1)
    deadline = time.monotonic() + 10.0  # on a busy machine the master's samples, taken on at rest, come later
    while recorder.samples < len(path) and time.monotonic() < deadline:
        time.sleep(0.02)
    final = np.abs(cobot.joint_state().positions - (start + MOVE))
    return recorder, final, np.array(path), rig.sim.backlog.take()


class _PlantLog:
    """What the plant was sent and did, step by step: the target its drives handed it and where the joints went."""

    def __init__(self, plant) -> None:
        self.targets: list[np.ndarray] = []
        self.positions: list[np.ndarray] = []
        step = plant.step

        def logged(dt: float) -> None:
            before = plant.joint_positions()
            step(dt)
            self.targets.append(plant._target.copy())
            self.positions.append(np.stack([before, plant.joint_positions()]))

        plant.step = logged


def test_csp_tracks_a_ruckig_trajectory(rig, robot):
    """Judged on the plant's side, against the setpoints it actually received, so that nothing depends on how fast
    the machine is: every target the drives handed the plant is a point of the streamed path, taken in order, the
    last one its end; and in every SYNC period each joint moved toward its target as the drive's position loop
    does (the first-order lag of the plant, to 1e-9 rad)."""
    log = _PlantLog(rig.plant)
    recorder, final, path, _ = _run_trajectory(rig, robot)
    with rig.sim.lock:  # the simulator goes on stepping the plant: one consistent look at the log
        targets, positions = np.array(log.targets), np.array(log.positions)
    moving = targets[np.any(np.abs(np.diff(targets, axis=0, prepend=targets[:1])) > 0, axis=1)]
    index = [int(np.argmin(np.abs(path - t).max(axis=1))) for t in moving]
    assert all(np.abs(path[i] - t).max() < 1e-6 for i, t in zip(index, moving))  # each one a setpoint streamed
    assert index == sorted(index) and index[-1] == len(path) - 1  # in order, to the end
    assert len(set(index)) > 0.9 * len(path)  # and almost every setpoint arrived on its own SYNC
    alpha = 1.0 - np.exp(-rig.cobot.period / rig.plant.params.joint_time_constant)
    before, after = positions[:, 0], positions[:, 1]
    assert np.abs(after - (before + (targets - before) * alpha)).max() < 1e-9
    assert final.max() < FINAL_TOLERANCE
    stats = rig.cobot.stats()
    assert stats.underruns == 0 and stats.refused_setpoints == 0
    assert rig.cobot.status().fault is None
    assert recorder.samples >= len(path)  # the master saw the motion too (its own error depends on reply timing)


def test_added_delay_is_counted_and_tolerated(rig, robot):
    # Replies 2.5 cycles late: the master cannot tell which SYNC they answer (SYNC carries no counter here),
    # so samples look up to 3 cycles older than assumed, and older by what the delay line's thread waited for the
    # CPU on a busy machine; the arm still follows and nothing faults.
    rig.sim.faults.set_delay(2.5 * rig.cobot.period)
    recorder, final, path, backlog = _run_trajectory(rig, robot)
    n = len(path)
    rig.sim.faults.set_delay(0.0)
    faults = rig.sim.stats().faults
    assert faults.delayed_tx > 13 * n
    assert rig.cobot.stats().lost_feedback > 0  # the gap when the delay set in was seen
    age = 3 * rig.cobot.period + faults.delay_overrun_s + backlog
    assert recorder.max_error.max() < LOSSY_TRACKING_TOLERANCE + age * robot.v_max.max(), (faults, backlog)
    assert final.max() < FINAL_TOLERANCE
    assert rig.cobot.status().fault is None


def test_tracking_survives_5_percent_frame_loss(rig, robot):
    rig.sim.faults.set_drop_rate(0.05, cyclic_only=True)
    recorder, final, path, backlog = _run_trajectory(rig, robot)
    n = len(path)
    rig.sim.faults.set_drop_rate(0.0)
    faults = rig.sim.stats().faults
    stats = rig.cobot.stats()
    assert faults.dropped_rx + faults.dropped_tx > 0.02 * n * 14
    assert stats.lost_feedback > 0  # the master saw and counted missing TPDOs
    assert recorder.max_error.max() < LOSSY_TRACKING_TOLERANCE + backlog * robot.v_max.max(), (
        recorder.max_error,
        backlog,
    )
    assert final.max() < FINAL_TOLERANCE
    assert rig.cobot.status().fault is None
