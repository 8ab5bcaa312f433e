"""The decision step the twin and the robot share: one clamp rule, IK failure holds, the task model judges."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.motion.decision import BAD_SHAPE, NON_FINITE, ActionError, DecisionStep
from mrguide.robot import RobotConfig, Workspace, load_robot
from mrguide.task import Outcome, TaskConfig, progress

PERIOD = 0.004


@pytest.fixture(scope="module")
def spec():
    return load_robot()


@pytest.fixture
def step(spec):
    s = DecisionStep(spec, TaskConfig(), PERIOD)
    s.reset(spec.q_home)
    return s


def test_one_clamp_rule_counted(step, spec):
    ws = spec.workspace
    cmd = step.act(np.array([1.5, -2.0, 0.3, 0.7]), spec.q_home)
    assert cmd.clamped and cmd.vacuum and cmd.q_target is not None
    assert np.allclose(cmd.target, ws.to_cartesian([1.0, -1.0, 0.3]))
    assert np.all(cmd.target >= ws.lo - 1e-12) and np.all(cmd.target <= ws.hi + 1e-12)
    assert step.state.clamped == 1
    cmd = step.act(np.array([0.2, 0.2, 0.2, 5.0]), spec.q_home)  # the gripper command is a sign, not clamped
    assert not cmd.clamped and cmd.vacuum and step.state.clamped == 1
    assert np.allclose(step.tcp(cmd.q_target), cmd.target, atol=1e-3)  # IK reached the target


@pytest.mark.parametrize(
    "bad, kind",
    [
        ([np.nan, 0, 0, 0], NON_FINITE),
        ([0, 0, np.inf, 1], NON_FINITE),
        ([0, 0, 0], BAD_SHAPE),
        ([[0, 0, 0, 0]], BAD_SHAPE),
    ],
)
def test_bad_action_is_refused_and_nothing_changes(step, spec, bad, kind):
    before = step.streamer.snapshot()
    with pytest.raises(ActionError) as info:
        step.act(np.array(bad, dtype=float), spec.q_home)
    assert info.value.kind == kind
    assert step.streamer.snapshot() == before and step.state.clamped == 0 and step.state.ik_failures == 0


def test_ik_failure_holds_the_arm_where_it_is():
    """A reachable target far away, then an unreachable one: the arm brakes to rest on the way (the hold),
    instead of going on to the first target."""
    spec = load_robot(RobotConfig(workspace=Workspace(low=(0.30, -0.20, 0.045), high=(1.40, 0.40, 0.35))))
    step = DecisionStep(spec, TaskConfig(), PERIOD)
    step.reset(spec.q_home)
    first = step.act(np.array([-1.0, 1.0, 0.0, -1.0]), spec.q_home)
    assert first.q_target is not None
    for _ in range(25):
        sp = step.streamer.step()
    assert np.max(np.abs(sp.dq)) > 0.1  # on its way
    held = step.act(np.array([1.0, 0.0, 0.5, -1.0]), sp.q)  # x = 1.4 m: out of reach
    assert held.q_target is None and "unreachable" in held.ik_error and step.state.ik_failures == 1
    for _ in range(2000):
        sp = step.streamer.step()
        if sp.finished or np.max(np.abs(sp.dq)) < 1e-9:
            break
    assert np.max(np.abs(sp.dq)) < 1e-9  # at rest
    assert np.max(np.abs(sp.q - first.q_target)) > 0.05  # short of the first target: held, not continued


def test_judge_counts_decisions_and_advances_the_phase(step, spec):
    obj, goal = np.array([0.5, -0.1, 0.025]), np.array([0.5, 0.2, 0.025])
    above = obj + [0.0, 0.0, 0.025 + TaskConfig().approach_height]  # the approach target: phase 0 done
    res = step.judge(above, -1, False, obj, goal)
    assert res.phase == 1 and res.outcome is None and step.state.t == 1 and step.phase == 1
    obs = step.observe(above, -1, obj, goal)
    assert obs[4] == pytest.approx(progress(1)) and np.allclose(obs[5:8], obj)
    for _ in range(TaskConfig().horizon - 1):
        res = step.judge(above, -1, False, obj, goal)
    assert res.outcome is Outcome.NO_GRASP and step.state.t == TaskConfig().horizon


def test_every_outcome_is_terminal_truncated_or_the_runtimes():
    task = {o for o in Outcome if o.from_task}
    assert {o for o in Outcome if o.terminated} | {o for o in Outcome if o.truncated} == task
    assert not any(o.terminated and o.truncated for o in Outcome)
    assert set(Outcome) - task == {Outcome.ABORTED, Outcome.POSE_LOST, Outcome.SAFETY_STOP}


def test_the_env_steps_through_the_decision_step(monkeypatch):
    from mrguide.twin.env import PickPlaceEnv

    calls = []
    act, judge = DecisionStep.act, DecisionStep.judge
    monkeypatch.setattr(DecisionStep, "act", lambda self, a, q: (calls.append("act"), act(self, a, q))[1])
    monkeypatch.setattr(DecisionStep, "judge", lambda self, *a: (calls.append("judge"), judge(self, *a))[1])
    env = PickPlaceEnv()
    try:
        env.reset(seed=0)
        env.step(env.expert_action())
        env.step(env.expert_action())
    finally:
        env.close()
    assert calls == ["act", "judge", "act", "judge"]
