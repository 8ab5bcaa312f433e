"""Eq. 4-6 term by term, phases, outcomes and progress, against hand-computed values."""

import numpy as np
import pytest

from mrguide.config import ConfigError
from mrguide.task import G_REQUIRED, Outcome, TaskConfig, phase_target, progress, task_step

CFG = TaskConfig(alpha=2.0, eta=1.5, step_penalty=0.1, epsilon=0.02, r_success=20.0, r_fail=10.0, horizon=50)
OBJ = np.array([0.5, -0.1, 0.025])
GOAL = np.array([0.5, 0.2, 0.025])


def test_required_gripper_states_and_bonuses_are_the_papers():
    assert G_REQUIRED == (-1, 1, 1, 1, -1)
    assert CFG.bonuses == (1.0, 2.0, 3.0, 4.0, 5.0)


def test_phase_targets():
    assert np.allclose(phase_target(0, OBJ, GOAL, CFG), [0.5, -0.1, 0.05 + 0.08])
    assert np.allclose(phase_target(1, OBJ, GOAL, CFG), [0.5, -0.1, 0.05])
    assert np.allclose(phase_target(2, OBJ, GOAL, CFG), [0.5, -0.1, 0.15])
    assert np.allclose(phase_target(3, OBJ, GOAL, CFG), [0.5, 0.2, 0.15])
    assert np.allclose(phase_target(4, OBJ, GOAL, CFG), [0.5, 0.2, 0.05])


def test_dense_term_step_penalty_and_premature_close():
    tcp = np.array([0.5, -0.1, 0.13 + 0.3])  # 0.3 m above the approach target
    r = task_step(CFG, 0, tcp, 1, False, OBJ, GOAL, t=0)
    assert r.terms["tracking"] == pytest.approx(-2.0 * 0.3)
    assert r.terms["premature_close"] == -1.5
    assert r.terms["step"] == -0.1
    assert r.reward == pytest.approx(-0.6 - 1.5 - 0.1)
    assert r.phase == 0 and r.outcome is None
    # gripper open in approach: no penalty
    assert task_step(CFG, 0, tcp, -1, False, OBJ, GOAL, t=0).terms["premature_close"] == 0.0
    # the closure penalty applies only in the approach phase
    assert task_step(CFG, 2, np.array([0.5, -0.1, 0.45]), 1, True, OBJ, GOAL, t=0).terms["premature_close"] == 0.0


def test_phase_bonus_needs_tolerance_and_gripper_state():
    at_target = np.array([0.5, -0.1, 0.13 + 0.01])  # d = 0.01 < ε
    done = task_step(CFG, 0, at_target, -1, False, OBJ, GOAL, t=3)
    assert done.terms["phase_bonus"] == 1.0 and done.phase == 1
    assert done.reward == pytest.approx(-2.0 * 0.01 + 1.0 - 0.1)
    wrong_grip = task_step(CFG, 0, at_target, 1, False, OBJ, GOAL, t=3)
    assert wrong_grip.terms["phase_bonus"] == 0.0 and wrong_grip.phase == 0
    far = task_step(CFG, 0, at_target + [0, 0, 0.05], -1, False, OBJ, GOAL, t=3)
    assert far.terms["phase_bonus"] == 0.0


def test_grasp_completes_only_with_a_part_on_the_cup():
    top = phase_target(1, OBJ, GOAL, CFG)
    assert task_step(CFG, 1, top, 1, False, OBJ, GOAL, t=5).phase == 1
    r = task_step(CFG, 1, top, 1, True, OBJ, GOAL, t=5)
    assert r.phase == 2 and r.terms["phase_bonus"] == 2.0


def test_success_terminal_reward():
    place = phase_target(4, GOAL, GOAL, CFG)
    r = task_step(CFG, 4, place, -1, False, GOAL, GOAL, t=20)
    assert r.outcome is Outcome.SUCCESS
    assert r.terms["phase_bonus"] == 5.0 and r.terms["terminal"] == 20.0
    assert r.reward == pytest.approx(0.0 + 5.0 - 0.1 + 20.0)
    assert progress(4, success=True) == 1.0


def test_failures():
    lifted = np.array([0.5, -0.1, 0.15])
    drop = task_step(CFG, 2, lifted, 1, False, OBJ, GOAL, t=9)
    assert drop.outcome is Outcome.DROPPED and drop.terms["terminal"] == -10.0
    drop_in_transport = task_step(CFG, 3, lifted, 1, False, OBJ, GOAL, t=9)
    assert drop_in_transport.outcome is Outcome.DROPPED
    # released 5 cm from the goal
    off = GOAL + [0.05, 0, 0]
    mis = task_step(CFG, 4, phase_target(4, off, off, CFG), -1, False, off, GOAL, t=20)
    assert mis.outcome is Outcome.MISPLACED and mis.terms["terminal"] == -10.0
    # horizon before grasp / after grasp
    assert task_step(CFG, 1, lifted, 1, False, OBJ, GOAL, t=49).outcome is Outcome.NO_GRASP
    assert task_step(CFG, 3, lifted, 1, True, OBJ, GOAL, t=49).outcome is Outcome.TIMEOUT
    assert task_step(CFG, 3, lifted, 1, True, OBJ, GOAL, t=48).outcome is None
    # a free object below the table surface was pushed off: the episode ends, whatever the phase
    fallen = OBJ - [0.0, 0.0, 0.03]
    for phase in (0, 1):
        knocked = task_step(CFG, phase, lifted, -1, False, fallen, GOAL, t=3)
        assert knocked.outcome is Outcome.KNOCKED_OFF and knocked.terms["terminal"] == -10.0
    assert task_step(CFG, 0, lifted, -1, False, OBJ, GOAL, t=3).outcome is None
    # held in the cup it is not knocked off (the carried object's estimate may dip with the TCP)
    assert task_step(CFG, 1, lifted, 1, True, fallen, GOAL, t=3).outcome is not Outcome.KNOCKED_OFF


def test_progress_indicator():
    assert [progress(k) for k in range(5)] == [0.0, 0.2, 0.4, 0.6, 0.8]


def test_bad_config_is_refused():
    with pytest.raises(ConfigError, match="epsilon"):
        TaskConfig(epsilon=0.0)
