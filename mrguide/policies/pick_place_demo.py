"""One pick-and-place demonstration's course through the five phases, from its fused pick and place points.

Each phase's waypoint follows from its point (`task.waypoint_from_mark`), moved by what the demonstration's earlier
phases found: an approach completed beside the pick point moves the grasp there, the lift rises above where the
grasp sealed, a transport completed beside the place point moves the release there. Where a waypoint does not
complete its phase, the demonstration searches around it (`waypoint_search`). The release sets the part down
towards `RELEASE_DEPTH` below the place point and opens the vacuum where the descent stops (the part stands on the
table), as a cell program sets a part down: a place mark above or below where the part comes to rest releases it
where it stands.

What a demonstration measured goes back to the fusion (`MarkFusion.add_measurement`): where the grasp sealed and
where the part was set down, each relative to its perceived anchor. The grasp is meant at the person's intent: where
a person taught it (`MarkFusion.intent`), else the centre prior, the part's centre. A grasp that sealed more than
`CENTRED` beside the intent — as the cell sees the part hanging from the cup through the lift — is measured at the
intent: a seal near the edge of the cup's reach holds in one demonstration and drops the part at the policy's next
wobble, and a seal the search found away from where the person pointed is not where they want the part gripped.
"""

from __future__ import annotations

import numpy as np

from mrguide.policies.waypoint_search import PATTERNS, WaypointSearch
from mrguide.task import OBS_OBJECT, OBS_TCP, PICK_PHASE, PLACE_PHASE, Phase, TaskConfig, mark_phase, waypoint_from_mark

#: m: a release descent that moved less than this in one decision has stopped: the part stands on the table.
CONTACT_STALL = 0.002
#: m: the release sets down this far below the place point and opens where the descent stops (ours).
RELEASE_DEPTH = 0.005
#: m: a grasp whose carried part the cell sees within this of the cup's axis is kept where it sealed (ours: about
#: half the twin's seal reach; a perceived offset below it is as likely the perception's error as the grasp's).
CENTRED = 0.006


class PickPlaceDemo:
    """The phase, the search and the corrections of the demonstration in progress."""

    def __init__(self, task: TaskConfig, intent: np.ndarray | None = None) -> None:
        """`intent`: m, x and y from the part's centre where the cup should meet it (None: the centre prior)."""
        self.task = task
        self.intent = np.zeros(2) if intent is None else np.asarray(intent, dtype=float)[:2]
        self.phase: int = Phase.APPROACH
        self.started = False  # the demonstration has made its first decision
        self.search: WaypointSearch | None = None
        #: m, the lateral corrections the demonstration's searches found so far, per kind of mark
        self.shift: dict[int, np.ndarray] = {PICK_PHASE: np.zeros(3), PLACE_PHASE: np.zeros(3)}
        self.sealed: np.ndarray | None = None  # the grasp target that sealed (m)
        self.released: np.ndarray | None = None  # where the part was set down (m)
        self._last_z: float | None = None  # the TCP height at the last release decision
        self._descending = False  # the release descent has begun (the TCP went down by CONTACT_STALL at least once)
        self._waypoint = np.zeros(3)  # this phase's waypoint before the search moved it
        self._carried: list[np.ndarray] = []  # the part's perceived xy from the TCP, per lift decision (m)

    def enter(self, phase: int, obs: np.ndarray) -> np.ndarray | None:
        """The observation `obs` is in `phase` now: close the phase it left. Where the grasp sealed: the pick point
        itself when it sealed as it was (no reason to move it); else laterally the probe that sealed (the commanded
        point: a measured one fed back as the next target would let the arm's lag accumulate), in height where the
        cup rests on the part now, its lip on the part's top. It is returned once the part was held through the lift
        (a grasp at the seal's edge drops it), at the intent if the lift saw it hang off it (`carried`)."""
        sealed = None
        tcp = np.asarray(obs[OBS_TCP], dtype=float)
        if phase == Phase.TRANSPORT and self.phase == Phase.LIFT and self.sealed is not None:
            sealed = self._centred(self.sealed)
        if self.started and phase > self.phase and self.search is not None:
            if self.phase == Phase.GRASP:
                offset = self.search.pressed_offset()
                self.sealed = self._waypoint + offset
                if np.any(offset):  # a probe sealed: press as far as the cup came down on the part
                    self.sealed[2] = tcp[2]
            elif self.search.probe > 0:  # approach, transport completed by the search: where, against the waypoint
                self.shift[mark_phase(self.phase)][:2] += tcp[:2] - self._waypoint[:2]
        self.phase, self.started = phase, True
        self.restart_phase()
        return sealed

    def carried(self, seen: np.ndarray) -> None:
        """A lift decision's observation with the part where the cell sees it: how far off the cup's axis it hangs."""
        if self.phase == Phase.LIFT:
            self._carried.append(np.asarray(seen[OBS_OBJECT][:2], dtype=float) - np.asarray(seen[OBS_TCP][:2]))

    def _centred(self, sealed: np.ndarray) -> np.ndarray:
        """`sealed` moved laterally onto the intent as seen through the lift (the part's centre `intent` from the
        cup's axis), if the part hung more than CENTRED off it; else as it sealed."""
        off = np.mean(self._carried, axis=0) + self.intent if self._carried else np.zeros(2)
        return sealed + np.r_[off, 0.0] if np.linalg.norm(off) > CENTRED else sealed

    def restart_phase(self) -> None:
        """Search this phase afresh (entering it, or after a new mark)."""
        pattern = PATTERNS.get(self.phase)
        self.search = WaypointSearch(pattern) if pattern is not None else None

    @property
    def probe(self) -> int:
        return self.search.probe if self.search is not None else 0

    def next_target(self, point: np.ndarray, seen: np.ndarray) -> np.ndarray | None:
        """The target (m) for this decision from this phase's fused point; None when its search found nothing.
        `seen` is the observation as the cell perceives it: the grasp's search is laid about the intent on the part
        it shows."""
        kind = mark_phase(self.phase)
        if self.phase == Phase.LIFT and self.sealed is not None:
            point = self.sealed
        else:
            point = np.asarray(point, dtype=float) + self.shift[kind]
        waypoint = self._waypoint = waypoint_from_mark(self.phase, point, self.task)
        if self.phase == Phase.RELEASE:
            waypoint = waypoint - [0.0, 0.0, RELEASE_DEPTH]
        if self.search is None:
            return waypoint
        return self.search.next_target(waypoint, np.asarray(seen[OBS_OBJECT], dtype=float) + np.r_[self.intent, 0.0])

    def opens_now(self, obs: np.ndarray, target: np.ndarray, opening: bool) -> bool:
        """Release: whether the vacuum opens at this decision — at the waypoint (`opening`, the annotation's rule) or
        where the descent towards it stopped short; the first opening is where the part was set down."""
        z = float(obs[OBS_TCP][2])
        drop = np.inf if self._last_z is None else self._last_z - z
        stalled = self._descending and drop < CONTACT_STALL and z - float(target[2]) > 0.5 * self.task.epsilon
        self._descending = self._descending or CONTACT_STALL <= drop < np.inf
        self._last_z = z
        opens = opening or stalled
        if opens and self.released is None:  # where the part comes to rest: the contact's height, not a lag's
            self.released = np.array([target[0], target[1], z])
        return opens
