"""The runtime's descent rule (deploy/descent_rule.py): the cup goes down only over the part, and does not slide while
it is down; a held part goes down only over its goal; elsewhere the policy's action passes unchanged."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.deploy.descent_rule import CARRY, CARRY_CLEARANCE, CLEARANCE, DESCENT, REACH, SLIDE, DescentRule
from mrguide.robot import load_robot
from mrguide.task import Phase

WS = load_robot().workspace
GRASP = np.array([0.50, -0.08, 0.05])  # the top centre of the block as seen
PLACE = np.array([0.46, 0.22, 0.05])  # where the cup stands when the block it holds rests at its goal
PLACE_REACH = 0.03  # the task's place tolerance


def action_to(xyz, g: float = 1.0) -> np.ndarray:
    return np.array([*WS.to_normalized(np.array(xyz, dtype=float)), g])


def target(action) -> np.ndarray:
    return WS.to_cartesian(np.clip(np.asarray(action)[:3], -1.0, 1.0))


def test_a_descent_beside_the_part_stops_at_the_clearance():
    rule, high = DescentRule(WS, PLACE_REACH), np.array([0.52, -0.08, 0.13])
    out, which = rule.apply(action_to([0.52, -0.08, 0.045]), high, GRASP, Phase.GRASP, False)
    assert which == DESCENT
    assert target(out) == pytest.approx([0.52, -0.08, GRASP[2] + CLEARANCE])  # over there, but clear of the top
    assert out[3] == 1.0


def test_a_descent_over_the_part_passes():
    rule, high = DescentRule(WS, PLACE_REACH), np.array([0.509, -0.08, 0.13])
    down = action_to([GRASP[0] + 0.9 * REACH, -0.08, 0.045])  # inside the reach of the grasp point
    assert rule.apply(down, high, GRASP, Phase.GRASP, False) == (down, None)


def test_a_cup_that_is_down_is_not_slid_sideways():
    rule, low = DescentRule(WS, PLACE_REACH), np.array([0.505, -0.08, 0.046])
    out, which = rule.apply(action_to([0.49, -0.09, 0.045]), low, GRASP, Phase.GRASP, False)
    assert which == DESCENT
    assert target(out)[:2] == pytest.approx(low[:2]) and target(out)[2] == pytest.approx(0.045)
    aim = action_to([0.505 + 0.8 * SLIDE, -0.08, 0.045])  # fine aim while down passes
    assert rule.apply(aim, low, GRASP, Phase.GRASP, False) == (aim, None)
    up = action_to([0.505, -0.08, 0.13], g=-1.0)  # straight up passes
    assert rule.apply(up, low, GRASP, Phase.GRASP, False) == (up, None)


@pytest.mark.parametrize("phase, done", [(Phase.LIFT, False), (Phase.GRASP, True)])
def test_after_the_grasp_or_when_done_the_action_passes(phase, done):
    rule, low = DescentRule(WS, PLACE_REACH), np.array([0.505, -0.08, 0.046])
    sideways = action_to([0.45, -0.02, 0.045])
    assert rule.apply(sideways, low, GRASP, phase, done) == (sideways, None)


def test_a_bad_action_passes_unchanged_for_the_decision_step_to_refuse():
    rule = DescentRule(WS, PLACE_REACH)
    for bad in (np.array([0.0, np.nan, 0.0, 1.0]), np.zeros(3)):
        out, which = rule.apply(bad, GRASP, GRASP, Phase.GRASP, False)
        assert out is bad and which is None


def test_a_held_part_short_of_its_goal_is_kept_above_the_table():
    """MuJoCo's dragged part (docs/results, lift drops): the target at the goal's height 10 cm short of it."""
    rule = DescentRule(WS, PLACE_REACH)
    short = action_to([0.46, 0.12, 0.045])
    out, which = rule.carry(short, PLACE, Phase.TRANSPORT, True)
    assert which == CARRY
    assert target(out) == pytest.approx([0.46, 0.12, PLACE[2] + CARRY_CLEARANCE])  # on its way, clear of the table
    assert out[3] == short[3]


def test_a_held_part_goes_down_over_its_goal_and_a_high_carry_passes():
    rule = DescentRule(WS, PLACE_REACH)
    down = action_to([0.46 + 0.9 * PLACE_REACH, 0.22, 0.05])  # within the place tolerance: set down
    assert rule.carry(down, PLACE, Phase.RELEASE, True) == (down, None)
    high = action_to([0.46, 0.05, PLACE[2] + CARRY_CLEARANCE + 0.001])  # far from the goal but clear of the table
    assert rule.carry(high, PLACE, Phase.TRANSPORT, True) == (high, None)


@pytest.mark.parametrize("phase, held", [(Phase.LIFT, True), (Phase.TRANSPORT, False), (Phase.GRASP, False)])
def test_the_carry_rule_acts_only_on_a_held_part_in_the_transport_and_the_release(phase, held):
    rule = DescentRule(WS, PLACE_REACH)
    short = action_to([0.46, 0.12, 0.045])
    assert rule.carry(short, PLACE, phase, held) == (short, None)
    for bad in (np.array([0.0, np.nan, 0.0, 1.0]), np.zeros(3)):
        out, which = rule.carry(bad, PLACE, Phase.TRANSPORT, True)
        assert out is bad and which is None
