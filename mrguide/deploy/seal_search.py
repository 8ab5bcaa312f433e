"""The runtime's seal search, applied on the robot and in every dry run whatever the policy commands.

A cup whose lip lands partly off the part's face never seals: the part is perceived a few millimetres off where
it lies (an HMD's registration error) and the policy, whose target follows the perceived part, keeps pressing
where it is until the episode's horizon. A cell program searches instead. While the cup presses without "vacuum
OK" — the arm at rest, the vacuum on and its level no longer rising — for `wait` decisions, the runtime re-seats
the cup over two decisions: the vacuum off with a blow-off pulse, the cup rises `RESEAT_LIFT` (a cup that does not
seal still pulls: pressed on the part's edge it drags the part along); then, the vacuum still off, it moves over
the point where a press now most likely seals — the registration's posterior (`bias_estimate.py`), which has taken
in this press and every earlier one, at least `step` from every point this search pressed; then it presses there as
the policy pressed (the height its action asked at the first re-seat), the vacuum on. From the first re-seat until
the seal the search owns the grasp: a policy that sees its vacuum off mid-grasp would go back up to approach again.
Each re-seat is reported (`RESEAT`) and counted with the episode's events; after `MAX_RESEATS` the cup stays at the
last point and the horizon ends the episode.

A seal kept where the policy pressed tells the registration little (only that the part's centre is within the
window), and one kept near the window's edge is a part the cell may lose in transport. So while the registration is
uncertain, a seal is a probe (`Prober`): the search lets it go as it lets go a cup that did not seal — `sensed` hides
it from the task model and the policy, so the grasp goes on — and presses next where a seal is as likely as not
(the press that tells the most), at most the episode's probes; then where a seal is most likely, and keeps that one.

Like the lift rules, the search only rewrites the action (its position, and its vacuum command while it re-seats);
the twin trains without it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from mrguide.deploy.bias_estimate import Registration
from mrguide.deploy.runtime_config import RuntimeConfig
from mrguide.drivers.cobot_state import VacuumState
from mrguide.robot import Workspace
from mrguide.task import ACT_DIM, Phase

#: What `SealSearch.apply` says when it re-seats the cup (also the safety event's name).
RESEAT = "reseat"
#: m the cup rises above where it pressed before it moves over the next point.
RESEAT_LIFT = 0.01
#: m: the TCP counts as at rest (pressed) when it moved less than this since the last decision.
AT_REST = 0.001
#: kPa: the vacuum counts as settled when its level rose less than this since the last decision.
SETTLED = 1.0
#: Re-seats a search makes at most (as many as the 5 mm hexagonal pattern it used to try had points).
MAX_RESEATS = 18
#: Where a re-seat stands: pressing (or watching the policy press), risen with the vacuum off, moved over the next point.
PRESSING, RISING, MOVING = "pressing", "rising", "moving"


#: The chooser of the next point: given the offsets (m, press − seen, k × 2) where this search pressed without a seal,
#: and whether the press is to inform (a probe) rather than to seal, the offset of the next press
#: (`Registration.next_press`).
Chooser = Callable[[np.ndarray, bool], np.ndarray]
#: Whether to probe on: given the probes made this episode, True while the registration is uncertain and the
#: episode's probes are not spent.
Prober = Callable[[int], bool]


class SealSearch:
    """Re-seats a cup that presses without a seal, and one that sealed while the registration is uncertain (a probe);
    one per runtime, `reset()` per episode. Each decision calls `sensed` first, then `apply`."""

    def __init__(self, workspace: Workspace, step: float, wait: int, choose: Chooser, probe: Prober):
        self.workspace, self.step, self.wait, self.choose, self.probe = workspace, step, wait, choose, probe
        self.reset()

    def reset(self) -> None:
        self._failed: list[np.ndarray] = []  # the offsets (m, press − seen) where this search's presses did not seal
        self._point = np.zeros(2)  # m: the point (xy) the search presses at now
        self._k = 0  # re-seats so far
        self.probes = 0  # presses made to inform this episode
        self._probing = False  # the press at the current point informs: its seal is let go
        self._release = False  # this decision lets a seal go
        self.sealed_press = False  # this decision's press holds a seal, kept or let go
        self._pressed = 0  # decisions in a row pressed without a seal
        self._stage = PRESSING
        self._height = 0.0  # m: the height the re-seat rises to
        self._press_height = 0.0  # m: the height the policy's action asked when the search began
        self._last: tuple[np.ndarray, float] | None = None  # (TCP, vacuum level) at the last decision

    @property
    def reseats(self) -> int:
        return self._k

    @property
    def blow_off(self) -> bool:
        """The last action released the cup: send the blow-off pulse with its vacuum-off command."""
        return self._stage == RISING

    def sensed(self, vac: VacuumState, phase: int) -> VacuumState:
        """The vacuum state as the task model and the policy are to see it this decision: a seal the search lets go
        (a probe's, or one while the registration is uncertain) and what is left of it while the cup re-seats is
        not reported as a part gripped."""
        seal = vac.part_gripped and phase == Phase.GRASP and self.step > 0
        pressing = self._stage == PRESSING
        self._release = seal and pressing and self._k < MAX_RESEATS and (self._probing or self.probe(self.probes))
        masked = self._release or (seal and not pressing)
        self.sealed_press = seal and (self._release or not masked)
        return replace(vac, part_gripped=False) if masked else vac

    def apply(
        self, action: np.ndarray, tcp: np.ndarray, seen: np.ndarray, phase: int, vac: VacuumState
    ) -> tuple[np.ndarray, str | None]:
        """(the action to run, RESEAT when this decision starts a re-seat, else None); `seen` is the pose source's
        part (xy used) that the chooser's offsets are from, `vac` as `sensed` returned it. Outside the grasp phase,
        with the vacuum commanded off, after a seal kept, or with the step 0, the action passes unchanged; an action
        the decision step will refuse (wrong shape, NaN) too."""
        a = np.asarray(action, dtype=float)
        tcp = np.asarray(tcp, dtype=float)
        last, self._last = self._last, (tcp, vac.level_kpa)
        if self.step <= 0 or a.shape != (ACT_DIM,) or not np.all(np.isfinite(a)):
            return action, None
        seen_xy = np.asarray(seen, dtype=float)[:2]
        if self._release:  # sealed while probing: let go and press elsewhere
            return self._reseat(a, tcp, seen_xy, sealed=True), RESEAT
        if phase != Phase.GRASP or vac.part_gripped or (a[3] <= 0 and self._k == 0):
            self._pressed, self._stage = 0, PRESSING
            return action, None
        if self._stage == RISING:  # risen: move over the next point, the vacuum still off
            self._probing = self.probe(self.probes)
            self.probes += int(self._probing)
            self._point = seen_xy + self.choose(np.array(self._failed), self._probing)
            self._stage = MOVING
            return self._retarget(a, self._height, vacuum=False), None
        if self._stage == MOVING:  # over it: press again as the policy pressed, the vacuum on
            self._stage, self._pressed = PRESSING, 0
        elif last is not None and self._at_rest(tcp, vac, last):
            self._pressed += 1
        else:
            self._pressed = 0
        if self._pressed >= self.wait and self._k < MAX_RESEATS:
            return self._reseat(a, tcp, seen_xy, sealed=False), RESEAT
        return (action, None) if self._k == 0 else (self._retarget(a, self._press_height), None)

    @staticmethod
    def _at_rest(tcp: np.ndarray, vac: VacuumState, last: tuple[np.ndarray, float]) -> bool:
        """Pressed without a seal: the vacuum on, its level settled, the TCP still since the last decision."""
        tcp_then, level_then = last
        still = float(np.linalg.norm(tcp - tcp_then)) < AT_REST
        return vac.vacuum_on and still and vac.level_kpa - level_then < SETTLED

    def _reseat(self, a: np.ndarray, tcp: np.ndarray, seen_xy: np.ndarray, sealed: bool) -> np.ndarray:
        """The first decision of a re-seat: the vacuum off, straight up `RESEAT_LIFT` from where the cup stands."""
        if self._k == 0:
            self._press_height = float(self.workspace.to_cartesian(np.clip(a[:3], -1.0, 1.0))[2])
        if not sealed:
            self._failed.append(tcp[:2] - seen_xy)
        self._k += 1
        self._release = False
        self._pressed, self._stage, self._height = 0, RISING, float(tcp[2]) + RESEAT_LIFT
        self._point = tcp[:2].copy()
        return self._retarget(a, self._height, vacuum=False)

    def _retarget(self, a: np.ndarray, height: float, vacuum: bool = True) -> np.ndarray:
        """The action aimed at the search's current point at `height` (m), the vacuum on or off."""
        target = np.array([*self._point, height])
        out = a.copy()
        out[:3] = np.clip(self.workspace.to_normalized(target), -1.0, 1.0)
        out[3] = 1.0 if vacuum else -1.0
        return out


def cell_search(
    cfg: RuntimeConfig, workspace: Workspace, registration: Registration, looks: Callable[[], int], exact: bool
) -> SealSearch:
    """The runtime's search as `[deploy.runtime]` sets it, its points from `registration` (its presses blurred by the
    pose source's `looks()` in the part's mean); no probes for an `exact` pose source."""
    probes = 0 if exact else cfg.registration_probes
    return SealSearch(
        workspace,
        cfg.reseat_step,
        cfg.reseat_wait,
        lambda failed, inform: registration.next_press(failed, cfg.reseat_step, looks(), inform),
        lambda made: made < probes and registration.uncertain(cfg.registration_spread),
    )
