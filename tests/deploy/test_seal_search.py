"""The runtime's seal search (deploy/seal_search.py): a cup pressed without a seal is re-seated on a hexagonal
pattern around where it pressed; a seal, a rising vacuum or a moving arm leaves the policy's action alone."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.deploy.seal_search import RESEAT, RESEAT_LIFT, RINGS, SealSearch, search_offsets
from mrguide.drivers.cobot_state import VacuumState
from mrguide.robot import load_robot
from mrguide.task import Phase

WS = load_robot().workspace
STEP, WAIT = 0.005, 2
PRESS = np.array([0.52, -0.10, 0.047])
PART = np.array([0.515, -0.113, 0.025])  # perceived a few mm off the press point


def vacuum(level: float = 8.0, gripped: bool = False, on: bool = True) -> VacuumState:
    return VacuumState(level, gripped, False, on, False, 0.0)


def press_action(g: float = 1.0) -> np.ndarray:
    """The policy pressing down on the part (its target below the part's top, clamped to the box floor)."""
    return np.array([*WS.to_normalized(np.array([0.52, -0.10, 0.0])), g])


def target(action) -> np.ndarray:
    return WS.to_cartesian(np.clip(np.asarray(action)[:3], -1.0, 1.0))


def run(search: SealSearch, decisions: int, vac: VacuumState, phase: int = Phase.GRASP, tcp=PRESS):
    return [search.apply(press_action(), tcp, PART, phase, vac) for _ in range(decisions)]


def test_the_pattern_is_two_hexagonal_rings_starting_toward_the_perceived_part():
    offsets = search_offsets(STEP, np.array([0.0, 1.0]))
    assert len(offsets) == 6 + 12 == sum(6 * k for k in range(1, RINGS + 1))
    radii = np.linalg.norm(offsets, axis=1)
    assert radii[:6] == pytest.approx([STEP] * 6)
    assert np.all((radii[6:] > STEP * 1.7) & (radii[6:] <= 2 * STEP + 1e-12))  # ring 2: corners 2 steps, sides √3
    assert offsets[0] == pytest.approx([0.0, STEP])  # the first point toward the part
    assert len({tuple(np.round(o, 9)) for o in offsets}) == len(offsets)


def test_a_cup_pressed_without_a_seal_is_released_lifted_moved_and_pressed_again():
    search = SealSearch(WS, STEP, WAIT)
    out = run(search, WAIT + 1, vacuum())  # the first decision has nothing to compare with
    assert [rule for _, rule in out[:WAIT]] == [None] * WAIT
    rise, rule = out[WAIT]
    assert rule == RESEAT and search.reseats == 1 and search.blow_off
    assert rise[3] < 0  # the vacuum off (with a blow-off pulse): a cup that does not seal still drags the part
    assert target(rise) == pytest.approx(PRESS + [0, 0, RESEAT_LIFT])  # straight up
    up = PRESS + [0, 0, RESEAT_LIFT]
    move, rule = search.apply(press_action(), up, PART, Phase.GRASP, vacuum(2.0, on=False))
    toward = (PART - PRESS)[:2] / np.linalg.norm((PART - PRESS)[:2])
    assert rule is None and move[3] < 0 and not search.blow_off
    assert target(move) == pytest.approx([*(PRESS[:2] + STEP * toward), up[2]])
    # the policy, seeing its vacuum off mid-grasp, asks to go back up with the vacuum off: the search owns the grasp
    # and presses where the policy pressed, the vacuum on
    back_up = np.array([*WS.to_normalized(np.array([0.4, -0.05, 0.3])), -1.0])
    press, rule = search.apply(back_up, target(move), PART, Phase.GRASP, vacuum(0.5, on=False))
    assert rule is None and press[3] > 0
    assert target(press) == pytest.approx([*target(move)[:2], target(press_action())[2]])


def test_every_point_is_tried_once_then_the_cup_stays_at_the_last():
    search = SealSearch(WS, STEP, WAIT)
    tcp, points = PRESS, []
    for _ in range(300):
        action, rule = search.apply(press_action(), tcp, PART, Phase.GRASP, vacuum())
        tcp = PRESS if rule == RESEAT else tcp  # a still cup: the search alone moves it
        if search.reseats and not search.blow_off and action[3] < 0:
            points.append(target(action)[:2])  # the move over the next point
    assert search.reseats == 18 and len(points) == 18
    assert np.array(points) == pytest.approx(PRESS[:2] + search_offsets(STEP, (PART - PRESS)[:2]))
    assert target(action)[:2] == pytest.approx(points[-1])


@pytest.mark.parametrize(
    "case",
    ["sealed", "vacuum rising", "vacuum off", "arm moving", "approach phase", "step 0"],
)
def test_no_reseat_while_the_seal_may_still_come_or_is_not_asked(case):
    search = SealSearch(WS, 0.0 if case == "step 0" else STEP, WAIT)
    phase = Phase.APPROACH if case == "approach phase" else Phase.GRASP
    for k in range(10):
        level = 8.0 + 5 * k if case == "vacuum rising" else 8.0
        vac = vacuum(70.0, True) if case == "sealed" else vacuum(level, on=case != "vacuum off")
        tcp = PRESS - [0, 0, 0.01 * k] if case == "arm moving" else PRESS
        g = -1.0 if case == "vacuum off" else 1.0
        action, rule = search.apply(press_action(g), tcp, PART, phase, vac)
        assert rule is None and np.array_equal(action, press_action(g))


def test_a_bad_action_passes_unchanged_for_the_decision_step_to_refuse():
    search = SealSearch(WS, STEP, WAIT)
    run(search, WAIT, vacuum())
    bad = np.array([np.nan, 0.0, 0.0, 1.0])
    assert search.apply(bad, PRESS, PART, Phase.GRASP, vacuum())[0] is bad


def test_where_a_search_sealed_is_tried_first_in_the_next_episode():
    search = SealSearch(WS, STEP, WAIT)
    for _ in range(12):  # two re-seats, then the seal
        search.apply(press_action(), PRESS, PART, Phase.GRASP, vacuum())
        if search.reseats == 2 and not search.blow_off:
            break
    sealed_at = search_offsets(STEP, (PART - PRESS)[:2])[1]
    search.apply(press_action(), PRESS, PART, Phase.LIFT, vacuum(70.0, True))
    assert search.hint == pytest.approx(sealed_at)
    search.reset()  # the next part, perceived off by the same error
    rise = next(a for a, rule in run(search, 5, vacuum()) if rule == RESEAT)
    move, _ = search.apply(press_action(), PRESS, PART, Phase.GRASP, vacuum(0.0, on=False))
    assert target(move)[:2] == pytest.approx(PRESS[:2] + sealed_at) and rise[3] < 0
    assert len(search_offsets(STEP, (PART - PRESS)[:2], sealed_at)) == 18  # a point of the same pattern: not twice
