"""Production cycles (deploy/cycles.py) on a scripted runtime: retries, alarms, skip, interrupt, resume counts.

The runtime here is a stand-in whose attempts end as a script says and whose part lies where the script puts it,
so every rule of the cycle runner is checked without threads or a bus (`./run.sh test` runs it in its parallel
pass); tests/cell/test_cycles_dry_run.py runs the same runner through the whole stack."""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np
import pytest

from mrguide.config import ConfigError
from mrguide.deploy.cycle_commands import cycles_done
from mrguide.deploy.cycles import CycleConfig, CycleRunner
from mrguide.deploy.episode import EpisodeReport, RunStopped
from mrguide.deploy.interrupt import CycleInterrupt
from mrguide.deploy.runlog import RunLog, RunLogError, read_log
from mrguide.drivers.cobot_state import DriverStats
from mrguide.pose_source import PoseUnavailable
from mrguide.task import Outcome, TaskConfig

ON_TABLE = np.array([0.5, -0.075, 0.025])


@dataclass
class ScriptedRuntime:
    """Attempts end with `outcomes` in turn; after each, the part lies at `positions` in turn (default: on the table
    in the pick region). A `RunStopped` in `outcomes` is raised instead."""

    outcomes: list
    log: RunLog
    positions: list = field(default_factory=list)
    task: TaskConfig = field(default_factory=TaskConfig)
    homes: int = 0
    departs: list = field(default_factory=list)  # the heights of the depart moves made
    can_depart: bool = True  # False: no joint configuration reaches the point above (an IK failure)
    episodes: list = field(default_factory=list)
    blind_reads: int = 0  # the pose source's next reads that have no pose
    missed: list = field(default_factory=list)  # control cycles the driver misses during each attempt in turn

    def __post_init__(self):
        self.pose, self.cobot = self, self
        self._where = ON_TABLE

    def object_position(self):
        if self._where is None or self.blind_reads > 0:
            self.blind_reads -= 1
            raise PoseUnavailable("marker not in view")
        return np.array(self._where, dtype=float)

    def stats(self):
        missed = sum(self.missed[: len(self.episodes)])
        return DriverStats(0, missed, *([0.0] * 5), *([0] * 12))

    def home(self):
        self.homes += 1

    def depart(self, height):
        if self.can_depart:
            self.departs.append(height)
        return self.can_depart

    def run_episode(self, goal, index):
        self.episodes.append(index)
        outcome = self.outcomes.pop(0)
        if isinstance(outcome, Exception):
            raise outcome
        self._where = self.positions.pop(0) if self.positions else ON_TABLE
        self.log.write("episode_end", episode=index, outcome=outcome.value)  # as the runtime does
        return EpisodeReport(index, outcome, 10, {})


class Feeder:
    def __init__(self, tracks_part=True):
        self.tracks_part, self.fed, self.cleared = tracks_part, [], []

    def next_part(self, cycle):
        self.fed.append(cycle)

    def clear_part(self, cycle):
        self.cleared.append(cycle)


def run(tmp_path, outcomes, count, config=None, positions=(), feeder=None, start=0, interrupt=None):
    log_path = tmp_path / "cycles.jsonl"
    with RunLog(log_path, {"test": "cycles"}) as log:
        rt = ScriptedRuntime(list(outcomes), log, list(positions))
        feeder = feeder or Feeder()
        runner = CycleRunner(rt, feeder, lambda c: np.array([0.5, 0.21, 0.025]), config or CycleConfig())
        summary = runner.run(start, count, interrupt)
    return summary, rt, feeder, read_log(log_path)


S, D, N = Outcome.SUCCESS, Outcome.DROPPED, Outcome.NO_GRASP


def test_each_cycle_feeds_a_part_and_places_it(tmp_path):
    summary, rt, feeder, records = run(tmp_path, [S, S, S], 3)
    assert summary.placed == 3 and not summary.retries() and summary.stopped is None
    assert feeder.fed == [0, 1, 2] and rt.episodes == [0, 1, 2]
    assert rt.homes == 3 and rt.departs == [0.05] * 3  # each place departs straight up; each attempt starts home
    ends = [r for r in records if r["kind"] == "cycle_end"]
    assert [(r["cycle"], r["placed"], r["outcomes"]) for r in ends] == [(c, True, ["success"]) for c in range(3)]
    assert all(10 < r["rss_mb"] < 100_000 for r in ends)  # the resident set after each cycle, MB (Linux)
    (final,) = [r for r in records if r["kind"] == "cycles_end"]
    assert final["placed"] == 3 and final["alarms"] == []


def test_each_cycle_records_the_control_cycles_missed_during_it(tmp_path):
    log_path = tmp_path / "cycles.jsonl"
    with RunLog(log_path, {"test": "cycles"}) as log:
        rt = ScriptedRuntime([S, D, S, S], log, missed=[0, 2, 1, 0])
        summary = CycleRunner(rt, Feeder(), lambda c: np.array([0.5, 0.21, 0.025]), CycleConfig()).run(0, 3)
    ends = [r for r in read_log(log_path) if r["kind"] == "cycle_end"]
    assert [r["missed_cycles"] for r in ends] == [0, 3, 0]  # cycle 1's two attempts missed 2 and 1
    assert all(r["steal_s"] is None or r["steal_s"] >= 0.0 for r in ends)  # the host's steal during it (Linux)
    assert all(r["io_stall_s"] is None or r["io_stall_s"] >= 0.0 for r in ends)  # /proc/pressure/io, if any
    assert all(r["major_faults"] >= 0 and r["preemptions"] >= 0 for r in ends)  # the process's own counters
    assert [r["work_overruns"] for r in ends] == [0, 0, 0]  # control cycles whose work ran past the period
    assert summary.missed_cycles == 3


def test_a_dropped_part_is_picked_again_and_the_retry_counted(tmp_path):
    summary, _rt, feeder, records = run(tmp_path, [D, N, S, S], 2)
    assert summary.placed == 2 and summary.retries() == {"dropped": 1, "no_grasp": 1}
    assert feeder.fed == [0, 1]  # no new part for a retry: the same one is picked where it lies
    retries = [(r["cycle"], r["attempt"], r["cause"]) for r in records if r["kind"] == "retry"]
    assert retries == [(0, 1, "dropped"), (0, 2, "no_grasp")]
    assert summary.cycles[0].outcomes == ["dropped", "no_grasp", "success"]


NO_HOMING = CycleConfig(home_between_cycles=False)


def test_without_homing_a_cycle_starts_where_the_arm_departed_a_retry_from_home(tmp_path):
    _summary, rt, _, _ = run(tmp_path, [S, S, S], 3, NO_HOMING)
    assert rt.homes == 1 and rt.departs == [0.05] * 3  # only the run's first attempt starts from home
    _summary, rt, _, _ = run(tmp_path, [S, D, S], 2, NO_HOMING)
    assert rt.homes == 2  # the run's first attempt, then the retry after the drop
    _summary, rt, _, _ = run(tmp_path, [S, S], 2, CycleConfig(depart_height=0.0, home_between_cycles=False))
    assert rt.homes == 2 and rt.departs == []  # no depart move: the arm stands in the place, so it homes


def test_a_depart_move_out_of_reach_or_a_part_unseen_from_there_sends_the_arm_home(tmp_path):
    class BlindAfterPlace(Feeder):
        def next_part(self, cycle):
            super().next_part(cycle)
            rt.blind_reads = 1 if cycle == 1 else 0  # the arm over the goal hides the part from the camera

    with RunLog(tmp_path / "blind.jsonl", {"test": "cycles"}) as log:
        rt = ScriptedRuntime([S, S, S], log)
        summary = CycleRunner(rt, BlindAfterPlace(), lambda c: np.zeros(3), NO_HOMING).run(0, 3)
    assert summary.placed == 3 and rt.homes == 2 and not any(c.alarm for c in summary.cycles)
    with RunLog(tmp_path / "reach.jsonl", {"test": "cycles"}) as log:
        rt = ScriptedRuntime([S, S], log, can_depart=False)
        CycleRunner(rt, Feeder(), lambda c: np.zeros(3), NO_HOMING).run(0, 2)
    assert rt.homes == 2


def test_too_many_failed_attempts_raise_an_alarm_that_stops_the_run(tmp_path):
    summary, _rt, feeder, records = run(tmp_path, [D, D, D], 5, CycleConfig(max_retries=2))
    assert summary.placed == 0 and len(summary.cycles) == 1
    assert summary.stopped == "alarm in cycle 0: 3 failed attempts (last: dropped)"
    assert [r["kind"] for r in records].count("alarm") == 1 and feeder.fed == [0]


def test_with_on_alarm_skip_the_part_is_left_for_the_operator_and_the_next_one_fed(tmp_path):
    summary, _rt, feeder, records = run(tmp_path, [D, D, S], 2, CycleConfig(max_retries=1, on_alarm="skip"))
    assert [c.placed for c in summary.cycles] == [False, True] and summary.stopped is None
    assert feeder.cleared == [0] and feeder.fed == [0, 1]
    (alarm,) = [r for r in records if r["kind"] == "alarm"]
    assert alarm["action"] == "skip" and alarm["cycle"] == 0


@pytest.mark.parametrize(
    ("where", "reason"),
    [
        ((0.5, 0.08, 0.025), "outside the pick region"),  # dropped in transport, between pick and goal regions
        ((0.5, -0.075, -0.2), "not resting on the table"),  # fell off the table
        (None, "no pose of the part for 0 s"),  # the pose source lost it
    ],
)
def test_a_part_that_cannot_be_picked_where_it_lies_raises_an_alarm(tmp_path, where, reason):
    summary, rt, _, _ = run(tmp_path, [D, S], 2, CycleConfig(pose_wait_s=0.0), positions=[where])
    assert reason in summary.cycles[0].alarm and summary.placed == 0 and len(rt.episodes) == 1


T = Outcome.TIMEOUT


@pytest.mark.parametrize(
    ("where", "placed"),
    [
        ((0.51, 0.22, 0.025), True),  # 14 mm off the goal, on the table: the cup set it down as the horizon ran out
        ((0.5, 0.245, 0.025), False),  # 35 mm off: beyond the task's 30 mm place tolerance, outside the pick region
        ((0.5, 0.21, 0.08), False),  # over the goal but 55 mm up: still on the cup, not placed
    ],
)
def test_a_part_seen_resting_at_its_goal_after_a_failed_attempt_is_placed(tmp_path, where, placed):
    summary, rt, _, records = run(tmp_path, [T, S], 1, CycleConfig(pose_wait_s=0.0), positions=[where])
    report = summary.cycles[0]
    assert report.placed is placed and report.outcomes == ["timeout"] and len(rt.episodes) == 1
    assert (report.alarm is None) is placed and not report.retries
    checks = [r for r in records if r["kind"] == "placed_on_check"]
    assert [(r["cycle"], r["part"]) for r in checks] == ([(0, list(where))] if placed else [])


@dataclass
class CoarseSourceRuntime(ScriptedRuntime):
    """The same, its pose source stating its accuracy (`PoseAccuracy`), as an HMD does from its registration."""

    accuracy: float = 0.022

    def accuracy_m(self):
        return self.accuracy


@pytest.mark.parametrize(("z", "alarm"), [(0.013, False), (0.037, False), (0.0, True), (-0.2, True)])
def test_the_resting_height_is_checked_no_finer_than_the_pose_source_sees(tmp_path, z, alarm):
    """A headset whose registration is good to 22 mm sees a part on the table 12 mm low or high (the MuJoCo cell's
    HMD did, raising alarms in a 1,000-cycle run); a part 25 mm off its height, or off the table, is still not
    picked."""
    with RunLog(tmp_path / "cycles.jsonl", {"test": "cycles"}) as log:
        rt = CoarseSourceRuntime([D, S], log, [(0.5, -0.075, z)])
        config = CycleConfig(pose_wait_s=0.0, max_retries=1)
        summary = CycleRunner(rt, Feeder(), lambda c: np.zeros(3), config).run(0, 1)
    assert ("not resting on the table" in (summary.cycles[0].alarm or "")) is alarm
    assert summary.placed == (0 if alarm else 1)


def test_a_source_that_states_no_accuracy_is_held_to_the_configured_tolerance(tmp_path):
    summary, *_ = run(tmp_path, [D, S], 2, CycleConfig(pose_wait_s=0.0), positions=[(0.5, -0.075, 0.013)])
    assert "not resting on the table" in summary.cycles[0].alarm


def test_the_arm_waits_at_home_for_a_pose_source_that_lost_its_view(tmp_path):
    log_path = tmp_path / "cycles.jsonl"
    with RunLog(log_path, {"test": "cycles"}) as log:
        rt = ScriptedRuntime([S], log, blind_reads=3)  # back after 3 reads (0.3 s of polling)
        runner = CycleRunner(rt, Feeder(), lambda c: np.zeros(3), CycleConfig(pose_wait_s=60.0))
        summary = runner.run(0, 1)
    assert summary.placed == 1 and rt.blind_reads == 0 and not summary.cycles[0].alarm


def test_a_pose_source_that_cannot_see_a_lost_part_raises_an_alarm(tmp_path):
    summary, *_ = run(tmp_path, [D, S], 1, feeder=Feeder(tracks_part=False))
    assert "cannot see where the part lies" in summary.cycles[0].alarm


def test_a_feeder_that_brings_no_part_raises_an_alarm(tmp_path):
    class Empty(Feeder):
        def next_part(self, cycle):
            raise PoseUnavailable("no part seen in the pick region within 30 s")

    summary, rt, _, records = run(tmp_path, [S], 2, feeder=Empty())
    assert summary.cycles[0].alarm == "no part came: no part seen in the pick region within 30 s"
    assert rt.episodes == [] and [r["kind"] for r in records][-2:] == ["cycle_end", "cycles_end"]


def test_a_part_knocked_off_is_gone_and_raises_an_alarm(tmp_path):
    summary, *_ = run(tmp_path, [Outcome.KNOCKED_OFF], 1)
    assert "knocked_off: the part is gone" in summary.cycles[0].alarm


def test_a_safety_stop_ends_the_run_with_its_reason_and_the_log_complete(tmp_path):
    summary, _rt, _, records = run(tmp_path, [S, RunStopped("drive_fault: EMCY from node 4")], 3)
    assert summary.stopped == "drive_fault: EMCY from node 4" and summary.placed == 1
    assert [r["kind"] for r in records][-2:] == ["cycle_end", "cycles_end"]


def test_an_interrupt_finishes_the_cycle_in_progress_then_stops(tmp_path):
    interrupt = CycleInterrupt()

    class Asking(Feeder):
        def next_part(self, cycle):
            super().next_part(cycle)
            if cycle == 1:
                interrupt.requested = True  # Ctrl-C while cycle 1 runs

    summary, *_ = run(tmp_path, [S, S, S], 3, feeder=Asking(), interrupt=interrupt)
    assert [c.cycle for c in summary.cycles] == [0, 1] and summary.placed == 2
    assert summary.stopped.startswith("interrupted")


def test_a_resumed_run_goes_on_from_the_log_count(tmp_path):
    _summary, _rt, feeder, _ = run(tmp_path, [S, S], 2, start=7)
    assert feeder.fed == [7, 8]
    assert cycles_done(tmp_path / "cycles.jsonl") == (9, 2)  # the next cycle, the next attempt's episode index
    with pytest.raises(RunLogError, match="no such run log"):
        cycles_done(tmp_path / "missing.jsonl")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"max_retries": -1}, "deploy.cycles.max_retries"),
        ({"on_alarm": "wait"}, "deploy.cycles.on_alarm"),
        ({"pick_region": ((0.6, 0.0), (0.4, 0.1))}, "deploy.cycles.pick_region[1][0]"),
        ({"rest_height_tolerance": float("nan")}, "deploy.cycles.rest_height_tolerance"),
        ({"pose_wait_s": -1.0}, "deploy.cycles.pose_wait_s"),
        ({"depart_height": 0.5}, "deploy.cycles.depart_height"),
        ({"home_between_cycles": "no"}, "deploy.cycles.home_between_cycles"),
    ],
)
def test_a_bad_cycle_config_is_refused_with_its_key(kwargs, message):
    with pytest.raises(ConfigError, match=message.replace("[", r"\[").replace("]", r"\]")):
        CycleConfig(**kwargs)


class FakeCamera:
    """Poses in turn, each captured now."""

    def __init__(self, positions):
        self.positions = iter(positions)

    def wait_for_pose(self, after, timeout):
        from mrguide.deploy.camera import TimedPose

        position = next(self.positions, None)
        if position is None:
            raise PoseUnavailable(f"no camera pose within {timeout} s")
        return TimedPose(np.array(position), after + 0.01)


def test_the_robot_feeder_waits_until_the_camera_sees_a_part_in_the_pick_region(monkeypatch):
    from mrguide.deploy import cycle_commands
    from mrguide.deploy.cycle_commands import RobotFeeder
    from mrguide.deploy.session import DeployConfig

    camera = FakeCamera([(0.5, 0.2, 0.025), (0.7, -0.05, 0.025), (0.5, -0.05, 0.025)])  # goal, outside, pick region
    RobotFeeder(camera, DeployConfig()).next_part(0)
    assert next(camera.positions, None) is None and RobotFeeder(camera, DeployConfig()).tracks_part
    monkeypatch.setattr(cycle_commands, "PART_WAIT_S", 0.05)
    with pytest.raises(PoseUnavailable, match=r"no part seen in the pick region within 0\.05 s"):
        RobotFeeder(FakeCamera(itertools.repeat((0.5, 0.2, 0.025))), DeployConfig()).next_part(1)
    with pytest.raises(PoseUnavailable, match="no camera pose"):
        RobotFeeder(FakeCamera([]), DeployConfig()).next_part(1)
    assert not RobotFeeder(None, DeployConfig()).tracks_part  # the fixed fixture pose cannot see a lost part
