"""The runtime's seal search (deploy/seal_search.py): a cup pressed without a seal is re-seated where its chooser
(the registration's posterior) says a press most likely seals; a seal, a rising vacuum or a moving arm leaves the
policy's action alone."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.deploy.seal_search import MAX_RESEATS, RESEAT, RESEAT_LIFT, SealSearch
from mrguide.drivers.cobot_state import VacuumState
from mrguide.robot import load_robot
from mrguide.task import Phase

WS = load_robot().workspace
STEP, WAIT = 0.005, 2
PRESS = np.array([0.52, -0.10, 0.047])
PART = np.array([0.515, -0.113, 0.025])  # perceived a few mm off the press point


class Chooser:
    """A stand-in for the registration: the k-th re-seat goes to offset (k · STEP, 0) from the seen part."""

    def __init__(self) -> None:
        self.asked: list[np.ndarray] = []
        self.inform: list[bool] = []

    def __call__(self, failed: np.ndarray, inform: bool) -> np.ndarray:
        self.asked.append(np.array(failed))
        self.inform.append(inform)
        return np.array([STEP * len(self.asked), 0.0])


def searcher(step: float = STEP, probes: int = 0) -> SealSearch:
    return SealSearch(WS, step, WAIT, Chooser(), lambda made: made < probes)


def vacuum(level: float = 8.0, gripped: bool = False, on: bool = True) -> VacuumState:
    return VacuumState(level, gripped, False, on, False, 0.0)


def press_action(g: float = 1.0) -> np.ndarray:
    """The policy pressing down on the part (its target below the part's top, clamped to the box floor)."""
    return np.array([*WS.to_normalized(np.array([0.52, -0.10, 0.0])), g])


def target(action) -> np.ndarray:
    return WS.to_cartesian(np.clip(np.asarray(action)[:3], -1.0, 1.0))


def step(search: SealSearch, action, tcp, vac: VacuumState, phase: int = Phase.GRASP):
    """One decision as the runtime makes it: the vacuum as the search lets it be seen, then the search's rule."""
    return search.apply(action, tcp, PART, phase, search.sensed(vac, phase))


def run(search: SealSearch, decisions: int, vac: VacuumState, phase: int = Phase.GRASP, tcp=PRESS):
    return [step(search, press_action(), tcp, vac, phase) for _ in range(decisions)]


def test_the_chooser_is_told_every_point_pressed_and_the_next_point_is_its_offset_from_the_seen_part():
    search = searcher()
    chooser = search.choose
    tcp = PRESS
    for _ in range(40):
        action, rule = step(search, press_action(), tcp, vacuum())
        tcp = target(action) if rule is None else tcp
        if search.reseats == 3:
            break
    assert isinstance(chooser, Chooser) and len(chooser.asked) == 2
    assert chooser.asked[0] == pytest.approx(
        np.array([(PRESS - PART)[:2]])
    )  # the policy's own press, from the seen part
    assert chooser.asked[1] == pytest.approx(np.array([(PRESS - PART)[:2], [STEP, 0.0]]))
    assert tcp[:2] == pytest.approx(PART[:2] + [2 * STEP, 0.0])


def test_a_cup_pressed_without_a_seal_is_released_lifted_moved_and_pressed_again():
    search = searcher()
    out = run(search, WAIT + 1, vacuum())  # the first decision has nothing to compare with
    assert [rule for _, rule in out[:WAIT]] == [None] * WAIT
    rise, rule = out[WAIT]
    assert rule == RESEAT and search.reseats == 1 and search.blow_off
    assert rise[3] < 0  # the vacuum off (with a blow-off pulse): a cup that does not seal still drags the part
    assert target(rise) == pytest.approx(PRESS + [0, 0, RESEAT_LIFT])  # straight up
    up = PRESS + [0, 0, RESEAT_LIFT]
    move, rule = step(search, press_action(), up, vacuum(2.0, on=False))
    assert rule is None and move[3] < 0 and not search.blow_off
    assert target(move) == pytest.approx([*(PART[:2] + [STEP, 0.0]), up[2]])  # the chooser's first point
    # the policy, seeing its vacuum off mid-grasp, asks to go back up with the vacuum off: the search owns the grasp
    # and presses where the policy pressed, the vacuum on
    back_up = np.array([*WS.to_normalized(np.array([0.4, -0.05, 0.3])), -1.0])
    press, rule = step(search, back_up, target(move), vacuum(0.5, on=False))
    assert rule is None and press[3] > 0
    assert target(press) == pytest.approx([*target(move)[:2], target(press_action())[2]])


def test_a_search_stops_after_its_last_reseat_and_the_cup_stays_at_the_last_point():
    search = searcher()
    tcp, points = PRESS, []
    for _ in range(300):
        action, rule = step(search, press_action(), tcp, vacuum())
        tcp = PRESS if rule == RESEAT else tcp  # a still cup: the search alone moves it
        if search.reseats and not search.blow_off and action[3] < 0:
            points.append(target(action)[:2])  # the move over the next point
    assert search.reseats == MAX_RESEATS and len(points) == MAX_RESEATS
    assert points[-1] == pytest.approx(PART[:2] + [MAX_RESEATS * STEP, 0.0])
    assert target(action)[:2] == pytest.approx(points[-1])


@pytest.mark.parametrize(
    "case",
    ["sealed", "vacuum rising", "vacuum off", "arm moving", "approach phase", "step 0"],
)
def test_no_reseat_while_the_seal_may_still_come_or_is_not_asked(case):
    search = searcher(0.0 if case == "step 0" else STEP)
    phase = Phase.APPROACH if case == "approach phase" else Phase.GRASP
    for k in range(10):
        level = 8.0 + 5 * k if case == "vacuum rising" else 8.0
        vac = vacuum(70.0, True) if case == "sealed" else vacuum(level, on=case != "vacuum off")
        tcp = PRESS - [0, 0, 0.01 * k] if case == "arm moving" else PRESS
        g = -1.0 if case == "vacuum off" else 1.0
        action, rule = step(search, press_action(g), tcp, vac, phase)
        assert rule is None and np.array_equal(action, press_action(g))


def test_a_bad_action_passes_unchanged_for_the_decision_step_to_refuse():
    search = searcher()
    run(search, WAIT, vacuum())
    bad = np.array([np.nan, 0.0, 0.0, 1.0])
    assert search.apply(bad, PRESS, PART, Phase.GRASP, vacuum())[0] is bad


def test_a_seal_while_the_registration_is_uncertain_is_let_go_and_the_next_presses_inform():
    search = searcher(probes=2)
    chooser = search.choose
    assert isinstance(chooser, Chooser)
    sealed = vacuum(40.0, gripped=True)
    seen = search.sensed(sealed, Phase.GRASP)
    assert not seen.part_gripped and search.sealed_press  # the task model does not see a grasp
    rise, rule = search.apply(press_action(), PRESS, PART, Phase.GRASP, seen)
    assert rule == RESEAT and rise[3] < 0 and search.blow_off
    assert target(rise) == pytest.approx(PRESS + [0, 0, RESEAT_LIFT])
    held = vacuum(30.0, gripped=True, on=False)  # what is left of the seal while the cup rises: still not a grasp
    move, _ = step(search, press_action(), PRESS + [0, 0, RESEAT_LIFT], held)
    assert chooser.inform == [True] and search.probes == 1 and chooser.asked[0].size == 0  # the seal failed nowhere
    press, _ = step(search, press_action(), target(move), vacuum(0.5, on=False))
    assert press[3] > 0
    rule = step(search, press_action(), target(press), sealed)[1]  # a probe's seal is let go too
    assert rule == RESEAT and search.reseats == 2
    step(search, press_action(), target(press), held)
    assert chooser.inform == [True, True] and search.probes == 2
    run(search, 1, vacuum(0.5, on=False))
    assert step(search, press_action(), target(press), sealed)[1] == RESEAT  # the second probe's seal, let go
    step(search, press_action(), target(press), held)
    assert chooser.inform == [True, True, False]  # the probes spent: where a seal is most likely
    run(search, 1, vacuum(0.5, on=False))
    kept = search.sensed(sealed, Phase.GRASP)  # and this seal is kept
    assert kept.part_gripped and search.sealed_press
    action, rule = search.apply(press_action(), PRESS, PART, Phase.GRASP, kept)
    assert rule is None and np.array_equal(action, press_action())


def test_without_probes_a_seal_is_reported_and_the_action_passes():
    search = searcher(probes=0)
    sealed = vacuum(40.0, gripped=True)
    seen = search.sensed(sealed, Phase.GRASP)
    assert seen.part_gripped and search.sealed_press
    action, rule = search.apply(press_action(), PRESS, PART, Phase.GRASP, seen)
    assert rule is None and np.array_equal(action, press_action())
    assert searcher(step=0.0, probes=3).sensed(sealed, Phase.GRASP).part_gripped  # the search off: probes too
