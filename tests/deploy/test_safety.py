"""Each safety reaction, provoked in a dry run and checked in the summary and the run log."""

import itertools
import time

import numpy as np
import pytest

from mrguide.deploy.runlog import read_log
from mrguide.deploy.runtime_config import RuntimeConfig
from mrguide.motion.trajectory import JointSetpoint, JointStreamer, TrajectoryError
from mrguide.pose_source import PoseUnavailable
from mrguide.robot import RobotConfig, Workspace, load_robot
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


def test_a_drive_falling_silent_mid_transport_quick_stops_and_names_it(run_dry):
    def silence_in_transport(obs, phase, a, cell):
        if phase == 3:
            cell.sim.faults.silence(5)  # elbow drive stops talking
        return a

    summary, log, cell = run_dry(hook=silence_in_transport)
    # whichever check sees it first names the drive: the heartbeat check node 5 (elbow_joint), the following-error
    # check (the silent drive's feedback froze while its setpoints moved on) the joint
    assert summary.stopped is not None and "elbow_joint" in summary.stopped
    ev = events(log)
    assert ev and ev[-1][0] in ("drive_fault", "following_error") and ev[-1][1] == "quick_stop"
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

    summary, log, _cell = run_dry(hook=stall)
    assert ("stall", "quick_stop") in events(log)
    assert summary.stopped is not None and "stall" in summary.stopped


def test_safety_stop_fails_its_episode_and_recovery_runs_the_next(run_dry):
    stalled = []

    def stall_once(obs, phase, a, cell):
        if phase == 1 and not stalled:
            stalled.append(True)
            time.sleep(0.6)
        return a

    summary, log, _cell = run_dry(episodes=2, hook=stall_once, max_recoveries=1)
    assert [e.outcome for e in summary.episodes] == ["safety_stop", "success"]
    assert summary.recoveries == 1 and summary.stopped is None
    kinds = [r["kind"] for r in read_log(log)]
    assert kinds.index("recovered") < len(kinds) - 1 - kinds[::-1].index("episode_end")


def test_recovery_fails_while_the_cause_persists(run_dry):
    def silence_in_transport(obs, phase, a, cell):
        if phase == 3:
            cell.sim.faults.silence(5)
        return a

    summary, _log, _ = run_dry(episodes=3, hook=silence_in_transport, max_recoveries=3)
    assert [e.outcome for e in summary.episodes] == ["safety_stop"]
    assert summary.recoveries == 0 and "recovery failed" in summary.stopped and "node 5" in summary.stopped


def decisions(log):
    return [r for r in read_log(log) if r["kind"] == "decision" and "obs" in r]


def test_action_outside_the_box_is_clamped_counted_and_logged(run_dry):
    ws = load_robot().workspace
    pushed = []

    def push_out_in_approach(obs, phase, a, cell):
        if phase == 0 and len(pushed) < 2:
            pushed.append(True)
            return np.array([1.7, -3.0, a[2], -1.0])  # x and y outside [-1, 1]
        return a

    summary, log, _ = run_dry(hook=push_out_in_approach)
    assert events(log)[:2] == [("workspace", "clamp")] * 2
    assert summary.episodes[0].events["workspace"] == 2 and summary.events()["workspace"] == 2
    clamped = [r for r in decisions(log) if abs(r["action"][0]) > 1]
    assert len(clamped) == 2
    for r in clamped:  # the target went to the box's edges, nowhere beyond
        assert r["target"][0] == pytest.approx(ws.hi[0]) and r["target"][1] == pytest.approx(ws.lo[1])
    assert summary.episodes[0].outcome == "success" and summary.stopped is None  # the episode went on


def _count_stops(cell, stops):
    """Record every quick stop the runtime commands on `cell`'s cobot."""
    if not stops:
        stop = cell.cobot.stop
        cell.cobot.stop = lambda: (stops.append(True), stop())[1]
        stops.append(False)


def test_following_error_quick_stops_the_run(run_dry):
    """Drive 4 reports its position 0.2 rad off (a slipped encoder): only the runtime's following-error
    monitor can see it (the drive's own check sees the true joint)."""
    stops = []

    def slip_in_lift(obs, phase, a, cell):
        _count_stops(cell, stops)
        if phase == 2:
            cell.sim.faults.set_position_error(4, 0.2)
        return a

    summary, log, _cell = run_dry(hook=slip_in_lift)
    ev = events(log)
    assert ev[-1] == ("following_error", "quick_stop"), ev
    assert summary.stopped is not None and "following_error" in summary.stopped
    assert summary.episodes[0].outcome == "safety_stop"
    assert stops.count(True) >= 1


def test_setpoint_beyond_a_joint_limit_quick_stops_before_it_is_sent(run_dry, monkeypatch):
    """A trajectory generator gone wrong: one setpoint 0.01 rad beyond joint 1's upper limit. The supervisor
    quick-stops the run and the setpoint never reaches the driver."""
    spec = load_robot()
    step = JointStreamer.step
    armed, sent = [], []

    def faulty_step(self):
        sp = step(self)
        if armed:
            q = sp.q.copy()
            q[0] = spec.q_upper[0] + 0.01
            return JointSetpoint(q, sp.dq, sp.ddq, sp.finished)
        return sp

    stops = []

    def arm_in_grasp(obs, phase, a, cell):
        _count_stops(cell, stops)
        if phase == 1 and not armed:
            armed.append(True)
            stream = cell.cobot.stream
            cell.cobot.stream = lambda q, timeout=None: (sent.append(np.array(q)), stream(q, timeout))[1]
        return a

    monkeypatch.setattr(JointStreamer, "step", faulty_step)
    summary, log, _cell = run_dry(hook=arm_in_grasp)
    ev = events(log)
    assert ev[-1] == ("joint_limit", "quick_stop"), ev
    assert summary.stopped is not None and "joint_limit" in summary.stopped
    assert summary.episodes[0].outcome == "safety_stop"
    assert stops.count(True) >= 1
    assert sent == [] or np.all(np.array(sent)[:, 0] <= spec.q_upper[0])


def test_a_trajectory_the_generator_cannot_plan_quick_stops_the_run(run_dry, monkeypatch):
    """Ruckig refuses to plan in the transport phase: the run quick-stops and logs why, instead of crashing with
    the drives enabled."""
    step = JointStreamer.step
    armed = []

    def failing_step(self):
        if armed:
            raise TrajectoryError("Ruckig cannot plan (test)")
        return step(self)

    def arm_in_transport(obs, phase, a, cell):
        if phase == 3:
            armed.append(True)
        return a

    monkeypatch.setattr(JointStreamer, "step", failing_step)
    summary, log, cell = run_dry(hook=arm_in_transport)
    assert events(log)[-1] == ("trajectory", "quick_stop")
    assert summary.stopped is not None and "Ruckig cannot plan (test)" in summary.stopped
    assert summary.episodes[0].outcome == "safety_stop"
    assert not cell.cobot.status().enabled


class _PoseGoesAway:
    """The exact pose until `fail()`, then PoseUnavailable (a marker out of view, a dead HMD process)."""

    def __init__(self, plant):
        self.plant, self.failing, self.given = plant, False, []

    def object_position(self):
        if self.failing:
            raise PoseUnavailable("tracking lost (test)")
        self.given.append(self.plant.object_position())
        return self.given[-1]


def test_missing_pose_uses_the_last_one_a_few_times_then_stops_the_episode(run_dry):
    sources = []

    def make_source(cell):
        sources.append(_PoseGoesAway(cell.plant))
        return sources[-1]

    def lose_in_grasp(obs, phase, a, cell):
        if phase == 1:
            sources[0].failing = True
        return a

    summary, log, cell = run_dry(
        hook=lose_in_grasp, pose=make_source, runtime_cfg=RuntimeConfig(max_pose_misses_before_grasp=3)
    )
    ev = events(log)
    assert ev == [("pose_unavailable", "last_known")] * 3 + [("pose_lost", "abort")], ev
    assert summary.episodes[0].outcome == "pose_lost" and summary.stopped is None  # the episode ended, cleanly
    # the part stood still: the mean of its poses (part_perception: a pose equal to the one before counts once), on
    # the table
    given = sources[0].given
    looks = [g for i, g in enumerate(given) if i == 0 or not np.array_equal(g, given[i - 1])]
    last = np.r_[np.mean(looks, axis=0)[:2], 0.5 * EnvConfig().task.object_height]
    blind = decisions(log)[-3:]  # the decisions made on the last pose
    assert all(np.allclose(r["obs"][5:8], last, atol=1e-6) for r in blind)
    ends = [r for r in read_log(log) if r["kind"] == "episode_end"]
    assert ends[-1]["outcome"] == "pose_lost" and ends[-1]["events"] == {"pose_unavailable": 3, "pose_lost": 1}
    assert cell.cobot.status().fault is None, cell.cobot.status().fault  # held (braked to rest), not quick-stopped


@pytest.mark.parametrize("lost_in", [0, 1, 3])
def test_before_the_grasp_the_last_pose_serves_longer(run_dry, lost_in):
    """The arm reaching for the part hides its marker: before the grasp (phases 0, 1) the last pose serves up to
    `max_pose_misses_before_grasp` decisions, and an occluded grasp succeeds; in transport (phase 3, the carried
    part tracked by the TCP) no pose is needed; after the release the short limit applies again."""
    sources = []

    def make_source(cell):
        sources.append(_PoseGoesAway(cell.plant))
        return sources[-1]

    def lose(obs, phase, a, cell):
        sources[0].failing = phase == lost_in
        return a

    summary, _log, _ = run_dry(
        hook=lose, pose=make_source, runtime_cfg=RuntimeConfig(max_pose_misses=2, max_pose_misses_before_grasp=30)
    )
    assert summary.episodes[0].outcome == "success", summary.text()
    misses = summary.episodes[0].events.get("pose_unavailable", 0)
    assert (misses > 2) if lost_in in (0, 1) else (misses == 0)


class _FrozenPose:
    """The pose at the start of the episode, forever (a tracker that lags far behind a carried object)."""

    def __init__(self, plant):
        self.plant, self.first = plant, None

    def object_position(self):
        if self.first is None:
            self.first = self.plant.object_position()
        return self.first.copy()


@pytest.mark.parametrize("track", [True, False])
def test_carried_object_is_placed_under_the_cup(run_dry, track):
    """While the vacuum generator reports a part after the grasp, the object is where the cup is (forward
    kinematics), not where a lagging pose source says; without the tracking the pose source is used."""
    frozen = []

    def make_source(cell):
        frozen.append(_FrozenPose(cell.plant))
        return frozen[-1]

    summary, log, _ = run_dry(pose=make_source, runtime_cfg=RuntimeConfig(track_carried_object=track))
    h = EnvConfig().task.object_height
    records = decisions(log)
    # the object position of a decision is found in the phase the previous decision left (the logged phase
    # is the one after this decision's task step)
    carried = [r for prev, r in itertools.pairwise(records) if prev["phase"] in (2, 3) and r["part"]]
    assert len(carried) >= 5
    # the source's pose less the registration the cell estimated from its presses so far (bias_estimate.py)
    corrections, correction = {}, np.zeros(3)
    for r in records:
        corrections[r["t"]] = correction
        if "bias_estimate" in r:
            correction = np.array([*r["bias_estimate"], 0.0])
    for r in carried:
        under_cup = np.array(r["obs"][0:3]) - [0.0, 0.0, 0.5 * h]
        if track:
            assert np.allclose(r["obs"][5:8], under_cup, atol=1e-6)
        else:
            seen = frozen[0].first - corrections[r["t"]]  # and at the height of a part on the table
            assert np.allclose(r["obs"][5:8], [seen[0], seen[1], 0.5 * h], atol=1e-6)
    if track:
        assert summary.episodes[0].outcome == "success", summary.text()
