"""Where a person's waypoint does not complete its phase, the demonstration searches, as a cell program would.

A person's marks carry a bias of their own (registration, depth): a pick mark 11 mm above the part's top or
15 mm beside its centre never seals (the cup's lip must rest whole on the top face, within 1 mm of it: 5 mm of
the centre per axis on the 5 cm part; `mrguide.seal`), and a waypoint more than ε = 2 cm from the task model's
target never completes its phase. The cell says which: the vacuum generator's part signal completes the grasp,
the part's pose the other phases. So a demonstration holds each waypoint for its phase's first dwell, then tries
the points of a 3 × 3 grid (`Pattern`), nearest first, until the phase completes:

- approach: a lateral grid around the waypoint at the approach height;
- grasp: a grid about where the cell sees the part's centre (its pose source, with that source's errors), each
  point first from `clearance` above, then pressed `depth` below the pick point (the workspace floor stops it;
  the cup's level-compensator takes up the rest), the way a suction cell's grasp searches for "vacuum OK" where
  its camera saw the part. Its pitch, 6 mm, is below the 10 mm window per axis in which the 20 mm lip rests whole
  on the 5 cm face, so a perception off by up to 8 mm per axis (5 mm + 1.5 pitches less the arm's lag) is covered;
- transport: a lateral grid around the waypoint at the lift height.

Lift and release have no search: the lift rises above where the cup sealed, and the release sets down under where
the transport arrived (a part set down on the table before the vacuum opens is released where it stands; see
`GuidedExpert`). Where a phase completed is a measurement of the person's bias, free of it: the guided expert
moves the rest of the demonstration by it, and records where the grasp sealed and where the part was placed.
The approach's and the transport's pitch is below the width of what completes their phase, so a waypoint off by up
to 1.5 pitches per axis lies within some probe's reach.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mrguide.task import Phase

#: Offsets of the probes in units of the pitch (lateral) and of the vertical step, nearest first: the grasp's and the
#: transport's grid; the approach's tries below and above the waypoint before the grid.
GRID = ((0, 0, 0), (1, 0, 0), (0, 1, 0), (-1, 0, 0), (0, -1, 0), (1, 1, 0), (-1, 1, 0), (-1, -1, 0), (1, -1, 0))
APPROACH_GRID = ((0, 0, -1), (0, 0, 1), *GRID[1:])


@dataclass(frozen=True)
class Pattern:
    """How one phase searches: dwell on the waypoint, then a grid of probes of `hover` + `press` decisions each."""

    first_dwell: int  # decisions on the waypoint itself (the scripted expert completes each phase within 7)
    pitch: float  # m, spacing of the grid (laterally, and vertically where the grid has vertical offsets)
    hover: int  # decisions `clearance` above each probe, so that moving over does not push the part
    press: int  # decisions at each probe, `depth` below the waypoint
    depth: float = 0.0  # m
    clearance: float = 0.0  # m
    grid: tuple[tuple[int, int, int], ...] = GRID
    #: the grid is laid about the part's centre as the cell sees it when the search begins, not about the waypoint
    about_seen: bool = False


#: The searches (ours): the approach's and the transport's pitch below √2 × the 2 cm phase tolerance ε (less for a
#: waypoint also off in height), the grasp's below the lip's 10 mm window (module docstring).
PATTERNS: dict[int, Pattern] = {
    Phase.APPROACH: Pattern(first_dwell=8, pitch=0.024, hover=0, press=2, grid=APPROACH_GRID),
    Phase.GRASP: Pattern(first_dwell=8, pitch=0.006, hover=1, press=2, depth=0.02, clearance=0.01, about_seen=True),
    Phase.TRANSPORT: Pattern(first_dwell=9, pitch=0.025, hover=0, press=2),
}


class WaypointSearch:
    """The targets of one phase of one demonstration, one per decision, around a fixed waypoint."""

    def __init__(self, pattern: Pattern) -> None:
        self.pattern = pattern
        self.steps = 0
        self.offset = np.zeros(3)  # the last target's offset from the waypoint (m)
        self._centre = np.zeros(3)  # the grid's centre, from the waypoint (m): where the cell saw the part, if so laid

    @property
    def probe(self) -> int:
        """The probe the last target belonged to: 0 for the waypoint itself, 1.. for the grid's points."""
        p = self.pattern
        if self.steps <= p.first_dwell:
            return 0
        return 1 + (self.steps - 1 - p.first_dwell) // (p.hover + p.press)

    def _probe_offset(self, k: int, pressed: bool) -> np.ndarray:
        """Probe k's target from the waypoint: pressed `depth` below it, or hovering `clearance` above."""
        p = self.pattern
        dx, dy, dz = p.grid[k]
        height = dz * p.pitch + (-p.depth if pressed else p.clearance)
        return self._centre + np.array([dx * p.pitch, dy * p.pitch, height])

    def pressed_offset(self) -> np.ndarray:
        """The offset from the waypoint of the last pressed target: the probe that completed the phase when it is found
        complete now. A target that only hovered over the next probe cannot have sealed; the part signal comes a
        decision after the press that made it."""
        p, last = self.pattern, self.steps - 1
        if last < p.first_dwell:
            return np.zeros(3)
        k, dwell = divmod(last - p.first_dwell, p.hover + p.press)
        if dwell < p.hover:
            k -= 1
        if k < 0:
            return np.zeros(3)
        return self._probe_offset(min(k, len(p.grid) - 1), pressed=True)

    def next_target(self, waypoint: np.ndarray, seen: np.ndarray | None = None) -> np.ndarray | None:
        """The target (m) for this decision, or None once every probe was tried without completing the phase.
        `seen` is the part's centre as the cell sees it now (m): a grid laid about it is laid at the first probe."""
        p, step = self.pattern, self.steps
        waypoint = np.asarray(waypoint, dtype=float)
        self.steps += 1
        if step < p.first_dwell:
            self.offset = np.zeros(3)
            return waypoint.copy()
        k, dwell = divmod(step - p.first_dwell, p.hover + p.press)
        if k >= len(p.grid):
            return None
        if step == p.first_dwell and p.about_seen and seen is not None:
            self._centre = np.array([seen[0] - waypoint[0], seen[1] - waypoint[1], 0.0])
        self.offset = self._probe_offset(k, pressed=dwell >= p.hover)
        return waypoint + self.offset
