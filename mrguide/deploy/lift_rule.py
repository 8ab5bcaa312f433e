"""The runtime's rules for the lift, applied on the robot and in every dry run whatever the policy commands.

- Vacuum OK: while the cup is on the part with the vacuum on but the generator does not yet report the part
  gripped (its "vacuum OK" / part-present signal, threshold L1 of the bus config), the arm does not rise: a
  partial seal is never lifted. The task model leaves the grasp phase only on that signal.
- Break-away: the first `break_away_distance` of the lift rises at most `break_away_speed`. A cup on a spring
  level-compensator is pressed in at the grasp; lifted fast, the compensator reaches its end stop with the part
  hanging under it and jerks the part at the arm's full speed: in the 'real' cell's twin, the drops in the lift
  were that jerk at full vacuum (docs/robot.md, production cycles).

- Hold in transit: a release asked while the part is held in the lift or the transport is not carried out: the
  vacuum stays on. The task model lets a part go only in the release phase, over its goal; anywhere before, a
  release is a dropped part, so refusing it can only keep a part that the policy would have dropped.

The first two only lower the height the action asks for, the third only keeps the vacuum on; the twin trains without
them (its rigid cup needs none, and a release in transit ends a training episode as a drop).
"""

from __future__ import annotations

import numpy as np

from mrguide.drivers.cobot_state import VacuumState
from mrguide.robot import Workspace
from mrguide.task import ACT_DIM, Phase

#: What `LiftRule.apply` and `hold_in_transit` say they did (also the safety events' names).
VACUUM_NOT_OK, BREAK_AWAY, HOLD_IN_TRANSIT = "vacuum_not_ok", "break_away", "hold_in_transit"


def _well_formed(action: np.ndarray) -> np.ndarray | None:
    """The action as floats, or None for one the decision step will refuse (wrong shape, NaN): the rules pass it on."""
    a = np.asarray(action, dtype=float)
    return a if a.shape == (ACT_DIM,) and np.all(np.isfinite(a)) else None


def hold_in_transit(action: np.ndarray, phase: int, vac: VacuumState) -> tuple[np.ndarray, str | None]:
    """(the action to run, HOLD_IN_TRANSIT if its release was refused, else None): in the lift and the transport,
    with the part reported gripped, a vacuum command g' <= 0 becomes +1. An action the decision step will refuse
    (wrong shape, NaN) is passed on unchanged for it to refuse."""
    a = _well_formed(action)
    if a is None:
        return action, None
    if phase in (Phase.LIFT, Phase.TRANSPORT) and a[3] <= 0 and vac.part_gripped:
        out = a.copy()
        out[3] = 1.0
        return out, HOLD_IN_TRANSIT
    return action, None


class LiftRule:
    """Lowers an action's height target where a lift rule applies; one per runtime, `reset()` per episode."""

    def __init__(self, workspace: Workspace, decision_period: float, distance: float, speed: float):
        self.workspace, self.rise_per_decision, self.distance = workspace, speed * decision_period, distance
        self.reset()

    def reset(self) -> None:
        self._seal_z: float | None = None  # the TCP's height at the first decision of the lift

    def apply(self, action: np.ndarray, tcp: np.ndarray, phase: int, vac: VacuumState) -> tuple[np.ndarray, str | None]:
        """(the action to run, the rule that lowered it or None). An action the decision step will refuse
        (wrong shape, NaN) is passed on unchanged for it to refuse."""
        a = _well_formed(action)
        if a is None:
            return action, None
        cap, rule = self._ceiling(a, float(tcp[2]), phase, vac)
        target = self.workspace.to_cartesian(np.clip(a[:3], -1.0, 1.0))
        if cap is None or target[2] <= cap:
            return action, None
        target[2] = cap
        out = a.copy()
        out[:3] = np.clip(self.workspace.to_normalized(target), -1.0, 1.0)  # a floor below the box: its floor
        return out, rule

    def _ceiling(self, a: np.ndarray, z: float, phase: int, vac: VacuumState) -> tuple[float | None, str | None]:
        """The highest target height allowed this decision, and which rule sets it (None: no limit)."""
        if phase == Phase.GRASP and a[3] > 0 and not vac.part_gripped:
            return z, VACUUM_NOT_OK
        if phase == Phase.LIFT:
            if self._seal_z is None:
                self._seal_z = z
            if z < self._seal_z + self.distance:
                return z + self.rise_per_decision, BREAK_AWAY
        return None, None
