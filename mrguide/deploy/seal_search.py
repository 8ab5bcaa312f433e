"""The runtime's seal search, applied on the robot and in every dry run whatever the policy commands.

A cup whose lip lands partly off the part's face never seals: the part is perceived a few millimetres off where
it lies (an HMD's registration error) and the policy, whose target follows the perceived part, keeps pressing
where it is until the episode's horizon. A cell program searches instead. While the cup presses without "vacuum
OK" — the arm at rest, the vacuum on and its level no longer rising — for `wait` decisions, the runtime re-seats
the cup over two decisions: the vacuum off with a blow-off pulse, the cup rises `RESEAT_LIFT` (a cup that does not
seal still pulls: pressed on the part's edge it drags the part along); then, the vacuum still off, it moves over the
point where a press now most likely seals — the registration's posterior (bias_estimate.py), which the failed press
has just updated, says where (`aim`) — and presses there as the policy pressed (the height its action asked at the
first re-seat), the vacuum on. Each failed press rules out where it pressed, so no point is pressed twice and the
search goes first where the part most likely is. From the first re-seat until the seal the search owns the grasp: a
policy that sees its vacuum off mid-grasp would go back up to approach again. Each re-seat is reported (`RESEAT`) and
counted with the episode's events; after `MAX_RESEATS` the cup stays and the horizon ends the episode.

Like the lift rules, the search only rewrites the action (its position, and its vacuum command while it re-seats);
the twin trains without it.
"""

from __future__ import annotations

import numpy as np

from mrguide.drivers.cobot_state import VacuumState
from mrguide.robot import Workspace
from mrguide.task import ACT_DIM, Phase

#: What `SealSearch.apply` says when it re-seats the cup (also the safety event's name).
RESEAT = "reseat"
#: m the cup rises above where it pressed before it moves to the next point.
RESEAT_LIFT = 0.01
#: m: the TCP counts as at rest (pressed) when it moved less than this since the last decision.
AT_REST = 0.001
#: kPa: the vacuum counts as settled when its level rose less than this since the last decision.
SETTLED = 1.0
#: Re-seats per grasp at most (a 60-decision horizon holds about ten).
MAX_RESEATS = 18
#: Where a re-seat stands: pressing (or watching the policy press), risen with the vacuum off, moved over the next point.
PRESSING, RISING, MOVING = "pressing", "rising", "moving"


class SealSearch:
    """Re-seats a cup that presses without a seal; one per runtime, `reset()` per episode."""

    def __init__(self, workspace: Workspace, wait: int, enabled: bool = True):
        self.workspace, self.wait, self.enabled = workspace, wait, enabled
        self.reset()

    def reset(self) -> None:
        self._point = np.zeros(2)  # m, xy: where the current re-seat presses
        self._k = 0  # re-seats so far
        self._pressed = 0  # decisions in a row pressed without a seal
        self._stage = PRESSING
        self._height = 0.0  # m: the height the re-seat rises to
        self._press_height = 0.0  # m: the height the policy's action asked when the search began
        self._last: tuple[np.ndarray, float] | None = None  # (TCP, vacuum level) at the last decision

    @property
    def reseats(self) -> int:
        return self._k

    @property
    def wants_aim(self) -> bool:
        """The next decision moves the cup over its next point: the only one that reads `aim`."""
        return self._stage == RISING

    @property
    def blow_off(self) -> bool:
        """The last action released the cup: send the blow-off pulse with its vacuum-off command."""
        return self._stage == RISING

    def apply(
        self, action: np.ndarray, tcp: np.ndarray, aim: np.ndarray | None, phase: int, vac: VacuumState
    ) -> tuple[np.ndarray, str | None]:
        """(the action to run, RESEAT when this decision starts a re-seat, else None); `aim` (m, xy): where a press
        most likely seals now (None: where the cup is). Outside the grasp phase, with the vacuum commanded off, after
        a seal, or with the search off, the action passes unchanged; an action the decision step will refuse (wrong
        shape, NaN) too."""
        a = np.asarray(action, dtype=float)
        tcp = np.asarray(tcp, dtype=float)
        last, self._last = self._last, (tcp, vac.level_kpa)
        if not self.enabled or a.shape != (ACT_DIM,) or not np.all(np.isfinite(a)):
            return action, None
        if phase != Phase.GRASP or vac.part_gripped or (a[3] <= 0 and self._k == 0):
            self._pressed, self._stage = 0, PRESSING
            return action, None
        if self._stage == RISING:  # risen: move over the next point, the vacuum still off
            self._stage = MOVING
            self._point = tcp[:2].copy() if aim is None else np.asarray(aim, dtype=float)[:2].copy()
            return self._retarget(a, self._height, vacuum=False), None
        if self._stage == MOVING:  # over it: press again as the policy pressed, the vacuum on
            self._stage, self._pressed = PRESSING, 0
        elif last is not None and self._at_rest(tcp, vac, last):
            self._pressed += 1
        else:
            self._pressed = 0
        if self._pressed >= self.wait and self._k < MAX_RESEATS:
            return self._reseat(a, tcp), RESEAT
        return (action, None) if self._k == 0 else (self._retarget(a, self._press_height), None)

    @staticmethod
    def _at_rest(tcp: np.ndarray, vac: VacuumState, last: tuple[np.ndarray, float]) -> bool:
        """Pressed without a seal: the vacuum on, its level settled, the TCP still since the last decision."""
        tcp_then, level_then = last
        still = float(np.linalg.norm(tcp - tcp_then)) < AT_REST
        return vac.vacuum_on and still and vac.level_kpa - level_then < SETTLED

    def _reseat(self, a: np.ndarray, tcp: np.ndarray) -> np.ndarray:
        """The first decision of a re-seat: the vacuum off, straight up `RESEAT_LIFT` from where the cup stands."""
        if self._k == 0:
            self._press_height = float(self.workspace.to_cartesian(np.clip(a[:3], -1.0, 1.0))[2])
        self._k += 1
        self._pressed, self._stage, self._height = 0, RISING, float(tcp[2]) + RESEAT_LIFT
        self._point = tcp[:2].copy()
        return self._retarget(a, self._height, vacuum=False)

    def _retarget(self, a: np.ndarray, height: float, vacuum: bool = True) -> np.ndarray:
        """The action aimed at the current point at `height` (m), the vacuum on or off."""
        out = a.copy()
        out[:3] = np.clip(self.workspace.to_normalized(np.array([*self._point, height])), -1.0, 1.0)
        out[3] = 1.0 if vacuum else -1.0
        return out
