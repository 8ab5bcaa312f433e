"""The runtime's lift rules (deploy/lift_rule.py): no rise before "vacuum OK", a slow break-away, no release in transit."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.deploy.lift_rule import BREAK_AWAY, HOLD_IN_TRANSIT, VACUUM_NOT_OK, LiftRule, hold_in_transit
from mrguide.drivers.cobot_state import VacuumState
from mrguide.robot import load_robot
from mrguide.task import Phase

WS = load_robot().workspace
PERIOD, DISTANCE, SPEED = 0.1, 0.015, 0.1


def vacuum(gripped: bool) -> VacuumState:
    return VacuumState(60.0 if gripped else 20.0, gripped, False, True, False, 0.0)


def action_to(xyz, g=1.0) -> np.ndarray:
    return np.array([*WS.to_normalized(np.array(xyz)), g])


def height(action) -> float:
    return float(WS.to_cartesian(np.asarray(action)[:3])[2])


def test_no_rise_while_the_vacuum_is_on_but_the_part_not_reported_gripped():
    rule, tcp = LiftRule(WS, PERIOD, DISTANCE, SPEED), np.array([0.5, -0.07, 0.06])
    out, which = rule.apply(action_to([0.5, -0.07, 0.2]), tcp, Phase.GRASP, vacuum(False))
    assert which == VACUUM_NOT_OK and height(out) == pytest.approx(0.06)
    assert np.allclose(WS.to_cartesian(out[:3])[:2], [0.5, -0.07]) and out[3] == 1.0  # only the height changes
    down = action_to([0.5, -0.07, 0.03])  # pressing on is not a lift
    assert rule.apply(down, tcp, Phase.GRASP, vacuum(False)) == (down, None)
    up_without_vacuum = action_to([0.5, -0.07, 0.2], g=-1.0)  # giving up on the grasp: the arm may rise
    assert rule.apply(up_without_vacuum, tcp, Phase.GRASP, vacuum(False))[1] is None


def test_the_lift_rises_slowly_for_its_first_millimetres_then_as_commanded():
    rule, goal = LiftRule(WS, PERIOD, DISTANCE, SPEED), action_to([0.5, 0.0, 0.25])
    z0 = 0.05
    out, which = rule.apply(goal, np.array([0.5, -0.07, z0]), Phase.LIFT, vacuum(True))
    assert which == BREAK_AWAY and height(out) == pytest.approx(z0 + SPEED * PERIOD)
    out, which = rule.apply(goal, np.array([0.5, -0.07, z0 + 0.01]), Phase.LIFT, vacuum(True))
    assert which == BREAK_AWAY and height(out) == pytest.approx(z0 + 0.01 + SPEED * PERIOD)
    assert rule.apply(goal, np.array([0.5, -0.07, z0 + DISTANCE]), Phase.LIFT, vacuum(True)) == (goal, None)
    rule.reset()  # a new episode measures from its own seal height
    assert rule.apply(goal, np.array([0.5, -0.07, 0.1]), Phase.LIFT, vacuum(True))[1] == BREAK_AWAY


@pytest.mark.parametrize("bad", [np.array([np.nan, 0.0, 0.0, 1.0]), np.zeros(3)])
def test_an_action_the_decision_step_refuses_is_passed_on_unchanged(bad):
    rule = LiftRule(WS, PERIOD, DISTANCE, SPEED)
    assert rule.apply(bad, np.array([0.5, -0.07, 0.06]), Phase.GRASP, vacuum(False)) == (bad, None)


def test_a_release_in_the_lift_or_transport_is_refused_while_the_part_is_held():
    release = action_to([0.55, 0.05, 0.2], g=-1.0)
    for phase in (Phase.LIFT, Phase.TRANSPORT):
        out, which = hold_in_transit(release, phase, vacuum(True))
        assert which == HOLD_IN_TRANSIT and out[3] == 1.0 and np.array_equal(out[:3], release[:3])
        assert hold_in_transit(release * [1, 1, 1, 0], phase, vacuum(True))[0][3] == 1.0  # g' = 0 is no "on" either
    assert hold_in_transit(release, Phase.RELEASE, vacuum(True)) == (release, None)  # over the goal: let go
    assert hold_in_transit(release, Phase.GRASP, vacuum(True)) == (release, None)  # giving up a grasp
    assert hold_in_transit(release, Phase.TRANSPORT, vacuum(False)) == (release, None)  # nothing held to keep
    keep = action_to([0.55, 0.05, 0.2])
    assert hold_in_transit(keep, Phase.TRANSPORT, vacuum(True)) == (keep, None)
    bad = np.array([0.0, np.nan, 0.0, -1.0])
    assert hold_in_transit(bad, Phase.TRANSPORT, vacuum(True))[0] is bad  # for the decision step to refuse
