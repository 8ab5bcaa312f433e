"""The runtime depends on `CobotInterface` alone: it runs an episode on a plain-Python cobot (no CAN, no
`Cobot`, no bus config), and its module does not import the concrete driver."""

from __future__ import annotations

import ast
from pathlib import Path

import numpy as np
import pytest

from mrguide.config import ConfigError
from mrguide.deploy.episode import RunStopped
from mrguide.deploy.runlog import RunLog, read_log
from mrguide.deploy.runtime import Runtime
from mrguide.deploy.runtime_config import RuntimeConfig
from mrguide.deploy.session import FixedObjectPose
from mrguide.drivers.cobot_state import DriverStats, JointState, VacuumState
from mrguide.drivers.errors import DriverError
from mrguide.drivers.interface import CobotInterface
from mrguide.errors import InputError
from mrguide.robot import load_robot
from mrguide.task import Outcome, TaskConfig, oracle_action


class IdealCobot:
    """An arm that is exactly where it was told to be, with a vacuum gripper that never grips."""

    period = 0.004
    setpoint_queue_depth = 4
    feedback_tolerance_cycles = 5

    def __init__(self, q):
        self.q, self.vacuum, self.streamed, self.observers = np.array(q, float), False, [], []

    @property
    def setpoint(self):
        return self.q.copy()

    def enable(self, timeout=None):
        pass

    def stream(self, q, timeout=None):
        self.q = np.array(q, float)
        self.streamed.append(self.q)

    def set_vacuum(self, on, blow_off=False):
        self.vacuum = bool(on)

    def stop(self):
        pass

    def reset_faults(self, timeout=None):
        pass

    def joint_state(self):
        return JointState(self.q.copy(), np.zeros_like(self.q), ("OPERATION ENABLED",) * len(self.q), 0, 0.0)

    def vacuum_state(self):
        return VacuumState(0.0, False, False, self.vacuum, False, 0.0)

    def stats(self):
        return DriverStats(*([0] * 2), *([0.0] * 5), *([0] * 12))

    def add_cycle_observer(self, observer):
        self.observers.append(observer)

    def remove_cycle_observer(self, observer):
        self.observers.remove(observer)


def test_runtime_runs_on_any_cobot_interface(tmp_path):
    spec, task = load_robot(), TaskConfig(horizon=8)
    cobot = IdealCobot(spec.q_home)
    assert isinstance(cobot, CobotInterface)
    policy = lambda obs: oracle_action(obs, task, spec.workspace.to_normalized)  # noqa: E731
    with (
        RunLog(tmp_path / "log.jsonl", {"test": "interface"}) as log,
        Runtime(cobot, policy, FixedObjectPose((0.5, -0.075, 0.025)), spec, task, log, 0.1, RuntimeConfig()) as rt,
    ):
        report = rt.run_episode(np.array([0.5, 0.21, 0.025]), 0)
    assert report.outcome is Outcome.NO_GRASP and report.decisions == task.horizon  # the cup never seals here
    (end,) = [r for r in read_log(tmp_path / "log.jsonl") if r["kind"] == "episode_end"]
    assert end["outcome"] == "no_grasp"  # the enum's value in the log
    assert len(cobot.streamed) >= task.horizon * 25
    first_phase = [r for r in read_log(tmp_path / "log.jsonl") if r["kind"] == "decision" and r.get("phase") == 1]
    assert first_phase  # the approach was reached by streaming through the interface


def test_runtime_module_does_not_import_the_concrete_cobot():
    tree = ast.parse((Path(__file__).parents[2] / "mrguide" / "deploy" / "runtime.py").read_text())
    modules = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
    modules |= {a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names}
    assert "mrguide.drivers.interface" in modules and "mrguide.drivers.cobot" not in modules


def test_a_driver_fault_outside_the_streaming_ends_the_episode_as_a_safety_stop(tmp_path):
    spec, task = load_robot(), TaskConfig(horizon=8)
    cobot = IdealCobot(spec.q_home)
    reads = []
    joint_state = cobot.joint_state

    def failing_joint_state():
        reads.append(1)
        if len(reads) == 3:
            raise DriverError("the control thread has held the driver lock for 0.5 s: it is hung (test)")
        return joint_state()

    cobot.joint_state = failing_joint_state
    policy = lambda obs: oracle_action(obs, task, spec.workspace.to_normalized)  # noqa: E731
    with (
        RunLog(tmp_path / "log.jsonl", {"test": "interface"}) as log,
        Runtime(cobot, policy, FixedObjectPose((0.5, -0.075, 0.025)), spec, task, log, 0.1, RuntimeConfig()) as rt,
        pytest.raises(DriverError, match="hung"),
    ):
        rt.run_episode(np.array([0.5, 0.21, 0.025]), 0)
    ends = [r for r in read_log(tmp_path / "log.jsonl") if r["kind"] == "episode_end"]
    assert [e["outcome"] for e in ends] == ["safety_stop"] and ends[0]["decisions"] == 2


class LaggingCobot(IdealCobot):
    """Joints that follow the setpoints through a first-order servo lag (`lag` s), `stuck` rad short on joint 0."""

    def __init__(self, q, lag, stuck=0.0):
        super().__init__(q)
        self.measured, self.lag, self.stuck = np.array(q, float), lag, stuck

    def stream(self, q, timeout=None):
        super().stream(q, timeout)
        self.measured += (1.0 - np.exp(-self.period / self.lag)) * (self.q - self.measured)

    def joint_state(self):
        q = self.measured.copy()
        q[0] -= self.stuck
        return JointState(q, np.zeros_like(q), ("OPERATION ENABLED",) * len(q), 0, 0.0)


@pytest.mark.parametrize("stuck, reaches", [(0.0, True), (0.02, False)])
def test_homing_waits_for_lagging_joints_then_judges(tmp_path, stuck, reaches):
    """With a 60 ms servo lag the joints are ~0.01 rad short when the last home setpoint is sent: homing holds home
    until they arrive (before, the run stopped there); a joint that never arrives still stops the run."""
    spec = load_robot()
    cobot = LaggingCobot(spec.q_home + 0.3, lag=0.06, stuck=stuck)
    policy = lambda obs: oracle_action(obs, TaskConfig(), spec.workspace.to_normalized)  # noqa: E731
    with (
        RunLog(tmp_path / "log.jsonl", {"test": "homing"}) as log,
        Runtime(cobot, policy, FixedObjectPose((0.5, -0.075, 0.025)), spec, TaskConfig(), log, 0.1) as rt,
    ):
        if reaches:
            rt.home()
            assert np.max(np.abs(cobot.joint_state().positions - spec.q_home)) <= rt.cfg.home_tolerance
        else:
            with pytest.raises(RunStopped, match="did not reach home within 1 s"):
                rt.home()


@pytest.mark.parametrize("decision_period", [0.006, 0.002, 0.1 + 1e-4])
def test_a_decision_period_off_the_control_cycle_is_bad_input(tmp_path, decision_period):
    """Refused as the CLI's bad input (ConfigError, an InputError: one line, exit 2), not as a bare ValueError."""
    spec = load_robot()
    policy = lambda obs: oracle_action(obs, TaskConfig(), spec.workspace.to_normalized)  # noqa: E731
    with (
        RunLog(tmp_path / "log.jsonl", {"test": "period"}) as log,
        pytest.raises(ConfigError, match=r"not a whole number of control periods \(0.004 s\)") as info,
    ):
        Runtime(
            IdealCobot(spec.q_home),
            policy,
            FixedObjectPose((0.5, -0.075, 0.025)),
            spec,
            TaskConfig(),
            log,
            decision_period,
        )
    assert isinstance(info.value, InputError) and f"decision period {decision_period} s" in str(info.value)


def test_a_decision_period_within_rounding_of_the_control_period_runs(tmp_path):
    """The tolerance `check_decision_period` grants the policy file (a period a hair below one control period)."""
    spec = load_robot()
    policy = lambda obs: oracle_action(obs, TaskConfig(), spec.workspace.to_normalized)  # noqa: E731
    with RunLog(tmp_path / "log.jsonl", {"test": "period"}) as log:
        rt = Runtime(
            IdealCobot(spec.q_home),
            policy,
            FixedObjectPose((0.5, -0.075, 0.025)),
            spec,
            TaskConfig(),
            log,
            0.004 * (1 - 5e-10),
        )
    assert rt.cycles == 1


def test_every_release_blows_off_for_one_decision(tmp_path):
    """A cup whose valve only closes stays evacuated for a second (the MuJoCo cell carried parts off on the depart
    move): the decision that turns the vacuum off sends a blow-off pulse, the next one ends it."""
    spec, task = load_robot(), TaskConfig(horizon=8)
    cobot = IdealCobot(spec.q_home)
    calls = []
    set_vacuum = cobot.set_vacuum
    cobot.set_vacuum = lambda on, blow_off=False: calls.append((bool(on), bool(blow_off))) or set_vacuum(on, blow_off)
    step = iter(range(100))

    def policy(obs):
        a = oracle_action(obs, task, spec.workspace.to_normalized)
        a[3] = 1.0 if next(step) in (2, 3) else -1.0  # vacuum on for two decisions, then off
        return a

    with (
        RunLog(tmp_path / "log.jsonl", {"test": "blow-off"}) as log,
        Runtime(cobot, policy, FixedObjectPose((0.5, -0.075, 0.025)), spec, task, log, 0.1, RuntimeConfig()) as rt,
    ):
        rt.run_episode(np.array([0.5, 0.21, 0.025]), 0)
    decisions = calls[: task.horizon]
    assert decisions[:5] == [(False, False), (False, False), (True, False), (True, False), (False, True)]
    assert decisions[5:] == [(False, False)] * (len(decisions) - 5)


def test_an_episode_that_ends_with_the_vacuum_on_blows_off_for_a_decision_before_the_arm_moves(tmp_path):
    """A cup pressed without a seal when the horizon runs out: a valve that only closed left it evacuated, and the
    home move carried the part off (the MuJoCo cell: a part hung under the cup at home, 0.2 m from the pick region)."""
    spec, task = load_robot(), TaskConfig(horizon=8)
    cobot = IdealCobot(spec.q_home)
    calls = []
    set_vacuum = cobot.set_vacuum

    def spy(on, blow_off=False):
        calls.append((bool(on), bool(blow_off), len(cobot.streamed)))
        set_vacuum(on, blow_off)

    cobot.set_vacuum = spy
    policy = lambda obs: oracle_action(obs, task, spec.workspace.to_normalized)  # noqa: E731  (presses, vacuum on)
    with (
        RunLog(tmp_path / "log.jsonl", {"test": "let go"}) as log,
        Runtime(cobot, policy, FixedObjectPose((0.5, -0.075, 0.025)), spec, task, log, 0.1, RuntimeConfig()) as rt,
    ):
        report = rt.run_episode(np.array([0.5, 0.21, 0.025]), 0)
        rt.home()
    assert report.outcome is Outcome.NO_GRASP
    pulse = next(i for i, (on, blow, _) in enumerate(calls) if blow)
    assert calls[pulse - 1][0] and not calls[pulse][0]  # the pulse follows the last decision's vacuum-on
    streamed_during = calls[pulse + 1][2] - calls[pulse][2]
    assert calls[pulse + 1][:2] == (False, False) and streamed_during == 25  # held a decision (25 cycles), then off
