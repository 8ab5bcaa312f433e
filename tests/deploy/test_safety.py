"""Each safety reaction, provoked in a dry run and checked in the summary and the run log."""

import time

import numpy as np

from mrguide.deploy.runlog import read_log
from mrguide.robot import RobotConfig, Workspace
from mrguide.twin.env import EnvConfig


def events(log):
    return [(r["event"], r["reaction"]) for r in read_log(log) if r["kind"] == "safety"]


def test_non_finite_action_aborts_the_episode(run_dry):
    def nan_in_grasp(obs, phase, a, cell):
        return np.array([np.nan, 0, 0, 1]) if phase == 1 else a

    summary, log, _ = run_dry(hook=nan_in_grasp)
    assert ("non_finite_action", "abort") in events(log)
    assert summary.episodes[0].outcome == "aborted" and summary.stopped is None


def test_unreachable_target_holds_then_aborts(run_dry):
    far = EnvConfig(robot=RobotConfig(workspace=Workspace(low=(0.30, -0.20, 0.045), high=(1.40, 0.40, 0.35))))

    def reach_out(obs, phase, a, cell):
        return np.array([1.0, 0.0, 0.5, -1.0])  # x = 1.4 m: beyond the UR5's reach

    summary, log, _ = run_dry(hook=reach_out, env_cfg=far)
    ev = events(log)
    assert ev[:2] == [("ik_failure", "hold"), ("ik_failure", "hold")]
    assert ("ik_failures_repeated", "abort") in ev
    assert summary.episodes[0].outcome == "aborted"


def test_heartbeat_loss_mid_transport_quick_stops_and_names_the_node(run_dry):
    def silence_in_transport(obs, phase, a, cell):
        if phase == 3:
            cell.sim.faults.silence(5)  # elbow drive stops talking
        return a

    summary, log, cell = run_dry(hook=silence_in_transport)
    assert summary.stopped is not None and "node 5" in summary.stopped
    ev = events(log)
    assert ev and ev[-1][0] == "drive_fault" and ev[-1][1] == "quick_stop"
    assert not cell.cobot.status().enabled


def test_vacuum_leak_in_lift_is_detected_as_a_drop(run_dry):
    def leak_in_lift(obs, phase, a, cell):
        if phase == 2:
            cell.sim.set_vacuum_leak(1.0)
        return a

    summary, log, _ = run_dry(hook=leak_in_lift)
    assert ("vacuum_lost", "abort") in events(log)
    assert summary.episodes[0].outcome == "dropped"


def test_stalled_decision_loop_triggers_the_watchdog(run_dry):
    def stall(obs, phase, a, cell):
        if phase == 1:
            time.sleep(0.6)
        return a

    summary, log, cell = run_dry(hook=stall)
    assert ("stall", "quick_stop") in events(log)
    assert summary.stopped is not None and "stall" in summary.stopped


def test_safety_stop_fails_its_episode_and_recovery_runs_the_next(run_dry):
    stalled = []

    def stall_once(obs, phase, a, cell):
        if phase == 1 and not stalled:
            stalled.append(True)
            time.sleep(0.6)
        return a

    summary, log, cell = run_dry(episodes=2, hook=stall_once, max_recoveries=1)
    assert [e.outcome for e in summary.episodes] == ["safety_stop", "success"]
    assert summary.recoveries == 1 and summary.stopped is None
    kinds = [r["kind"] for r in read_log(log)]
    assert kinds.index("recovered") < len(kinds) - 1 - kinds[::-1].index("episode_end")


def test_recovery_fails_while_the_cause_persists(run_dry):
    def silence_in_transport(obs, phase, a, cell):
        if phase == 3:
            cell.sim.faults.silence(5)
        return a

    summary, log, _ = run_dry(episodes=3, hook=silence_in_transport, max_recoveries=3)
    assert [e.outcome for e in summary.episodes] == ["safety_stop"]
    assert summary.recoveries == 0 and "recovery failed" in summary.stopped and "node 5" in summary.stopped
