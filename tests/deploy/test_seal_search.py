"""The runtime's seal search (deploy/seal_search.py): a cup pressed without a seal is re-seated where a press most
likely seals (the registration's aim); a seal, a rising vacuum or a moving arm leaves the policy's action alone."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.deploy.bias_estimate import BiasEstimate, SealWindow
from mrguide.deploy.seal_search import MAX_RESEATS, RESEAT, RESEAT_LIFT, SealSearch
from mrguide.drivers.cobot_state import VacuumState
from mrguide.robot import load_robot
from mrguide.task import Phase

WS = load_robot().workspace
WAIT = 2
PRESS = np.array([0.52, -0.10, 0.047])
AIM = np.array([0.515, -0.106])  # where the registration says a press most likely seals


def vacuum(level: float = 8.0, gripped: bool = False, on: bool = True) -> VacuumState:
    return VacuumState(level, gripped, False, on, False, 0.0)


def press_action(g: float = 1.0) -> np.ndarray:
    """The policy pressing down on the part (its target below the part's top, clamped to the box floor)."""
    return np.array([*WS.to_normalized(np.array([0.52, -0.10, 0.0])), g])


def target(action) -> np.ndarray:
    return WS.to_cartesian(np.clip(np.asarray(action)[:3], -1.0, 1.0))


def run(search: SealSearch, decisions: int, vac: VacuumState, phase: int = Phase.GRASP, tcp=PRESS):
    return [search.apply(press_action(), tcp, AIM, phase, vac) for _ in range(decisions)]


def test_a_cup_pressed_without_a_seal_is_released_lifted_moved_and_pressed_again():
    search = SealSearch(WS, WAIT)
    out = run(search, WAIT + 1, vacuum())  # the first decision has nothing to compare with
    assert [rule for _, rule in out[:WAIT]] == [None] * WAIT
    rise, rule = out[WAIT]
    assert rule == RESEAT and search.reseats == 1 and search.blow_off
    assert rise[3] < 0  # the vacuum off (with a blow-off pulse): a cup that does not seal still drags the part
    assert target(rise) == pytest.approx(PRESS + [0, 0, RESEAT_LIFT])  # straight up
    up = PRESS + [0, 0, RESEAT_LIFT]
    move, rule = search.apply(press_action(), up, AIM, Phase.GRASP, vacuum(2.0, on=False))
    assert rule is None and move[3] < 0 and not search.blow_off
    assert target(move) == pytest.approx([*AIM, up[2]])  # over the aim, at the risen height
    # the policy, seeing its vacuum off mid-grasp, asks to go back up with the vacuum off: the search owns the grasp
    # and presses where the policy pressed, the vacuum on
    back_up = np.array([*WS.to_normalized(np.array([0.4, -0.05, 0.3])), -1.0])
    press, rule = search.apply(back_up, target(move), AIM + 0.01, Phase.GRASP, vacuum(0.5, on=False))
    assert rule is None and press[3] > 0
    assert target(press) == pytest.approx([*AIM, target(press_action())[2]])  # the aim is read once per re-seat


def test_the_search_presses_where_the_posterior_says_and_finds_a_part_a_centimetre_off():
    """Driven by the registration's posterior, as the runtime drives it: each failed press rules out where it
    pressed, and the seal comes within a few re-seats for a part 8 and 6 mm off where it was seen."""
    window = SealWindow((0.0, 0.0), (0.005, 0.005))
    est, search = BiasEstimate(window), SealSearch(WS, 1)
    seen, part = np.array([0.52, -0.10]), np.array([0.512, -0.094])
    tcp, presses, missed = np.array([*seen, 0.047]), [], []
    for _ in range(60):
        sealed = bool(np.all(np.abs(tcp[:2] - part) < window.half))
        vac = vacuum(70.0, True) if sealed else vacuum()
        action, rule = search.apply(press_action(), tcp, seen + est.best_press(missed, 0.0015), Phase.GRASP, vac)
        if sealed:
            break
        if rule == RESEAT:
            presses.append(tcp[:2].copy())
            missed.append(tcp[:2] - seen)
            est.press(tcp, seen, False, 0.0015)
        tcp = target(action) if search.reseats else tcp  # the arm goes where the search sends it
    assert sealed and search.reseats <= 6, presses
    assert len({tuple(np.round(p, 4)) for p in presses}) == len(presses)  # no point pressed twice


def test_after_the_last_reseat_the_cup_stays():
    search = SealSearch(WS, WAIT)
    tcp = PRESS
    for _ in range(400):
        action, rule = search.apply(press_action(), tcp, AIM, Phase.GRASP, vacuum())
        tcp = PRESS if rule == RESEAT else tcp  # a still cup: the search alone moves it
    assert search.reseats == MAX_RESEATS
    assert target(action)[:2] == pytest.approx(AIM) and action[3] > 0  # pressing at the last point


@pytest.mark.parametrize(
    "case",
    ["sealed", "vacuum rising", "vacuum off", "arm moving", "approach phase", "search off"],
)
def test_no_reseat_while_the_seal_may_still_come_or_is_not_asked(case):
    search = SealSearch(WS, WAIT, enabled=case != "search off")
    phase = Phase.APPROACH if case == "approach phase" else Phase.GRASP
    for k in range(10):
        level = 8.0 + 5 * k if case == "vacuum rising" else 8.0
        vac = vacuum(70.0, True) if case == "sealed" else vacuum(level, on=case != "vacuum off")
        tcp = PRESS - [0, 0, 0.01 * k] if case == "arm moving" else PRESS
        g = -1.0 if case == "vacuum off" else 1.0
        action, rule = search.apply(press_action(g), tcp, AIM, phase, vac)
        assert rule is None and np.array_equal(action, press_action(g))


def test_a_bad_action_passes_unchanged_for_the_decision_step_to_refuse():
    search = SealSearch(WS, WAIT)
    run(search, WAIT, vacuum())
    bad = np.array([np.nan, 0.0, 0.0, 1.0])
    assert search.apply(bad, PRESS, AIM, Phase.GRASP, vacuum())[0] is bad
