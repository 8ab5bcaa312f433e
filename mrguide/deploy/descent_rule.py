"""The runtime's descent rule, applied on the robot and in every dry run whatever the policy commands.

A cup that moves sideways while it is down at the part pushes the part: pressed on the face's edge or beside it, the
lip drags it along, and a policy whose target follows the part as it is seen then chases it across the table. In the
MuJoCo cell, in each of the 5 failures of a probe of Fig. 8's seed-1 policy (76 episodes, exact poses), the part had
been pushed 75–168 mm before a seal (docs/robot.md, the descent rule). A cell program never slides its tool across the part: it moves over the part, then goes
straight down. So, before the part is held and until the seal search takes over:

- a target farther than `REACH` from the grasp point as seen keeps at least `CLEARANCE` above it: the cup goes down
  only over the part;
- with the cup down (the TCP below that clearance), a target more than `SLIDE` to the side of the TCP is not followed
  sideways: the cup stays where it is down, at the height the action asks. Pressed with the vacuum on, it comes to
  rest there (the lift rule keeps it from rising without a seal), and the seal search re-seats it as a cell program
  would, the vacuum off and the cup raised before it moves; with the vacuum off, the policy may raise it and move over.

The part goes down only over its goal, as the cup goes down only over the part: while the part is held (the transport
and the release), a target farther than the task's place tolerance from where the cup places it keeps the part's
underside `CARRY_CLEARANCE` above the table. In the MuJoCo cell a policy once aimed at the goal's height 10 cm short
of it, and the part met the table and was dragged until the seal broke (docs/results: lift drops over 200 episodes);
a cell program carries a part clear of the table and sets it down over its place.

Like the lift rules, they only rewrite the action's position; the twin trains without them.
"""

from __future__ import annotations

import numpy as np

from mrguide.robot import Workspace
from mrguide.task import ACT_DIM, Phase

#: What `DescentRule.apply` says when it rewrote the action (also the safety event's name).
DESCENT = "descent"
#: m above the grasp point (the face where the lip meets it) the cup keeps while it is not over it: the lip clear of
#: the part's top, the cup's 5 mm of compensator stroke included.
CLEARANCE = 0.01
#: m from the grasp point as seen within which the cup may go down: twice the 5 mm the 20 mm lip may miss the 5 cm
#: block's centre by and still seal (`mrguide.seal`), so that a first press off by the pose's error lands on the face.
REACH = 0.01
#: m the cup may move sideways per decision while it is down: fine aim, not a push.
SLIDE = 0.002
#: What `DescentRule.carry` says when it rewrote the action (also the safety event's name).
CARRY = "carry"
#: m the held part's underside keeps above the table until the part is over its goal.
CARRY_CLEARANCE = 0.01


class DescentRule:
    """Keeps the cup above the part until it is over it, and still sideways while it is down; keeps a held part above
    the table until it is over its goal (`carry`)."""

    def __init__(self, workspace: Workspace, place_reach: float):
        """`place_reach`: m from where the cup places the part within which a held part may go down (the task's place
        tolerance: a part set down there is placed)."""
        self.workspace, self.place_reach = workspace, place_reach

    def apply(
        self, action: np.ndarray, tcp: np.ndarray, grasp: np.ndarray, phase: int, done: bool
    ) -> tuple[np.ndarray, str | None]:
        """(the action to run, DESCENT if it was rewritten, else None); `grasp` is where the cup meets the part as seen
        (m); `done`: the part is held, or the seal search owns the grasp. Outside the approach and the grasp, or when
        done, the action passes unchanged; an action the decision step will refuse (wrong shape, NaN) too."""
        a = np.asarray(action, dtype=float)
        if done or phase > Phase.GRASP or a.shape != (ACT_DIM,) or not np.all(np.isfinite(a)):
            return action, None
        tcp, grasp = np.asarray(tcp, dtype=float), np.asarray(grasp, dtype=float)
        target = self.workspace.to_cartesian(np.clip(a[:3], -1.0, 1.0))
        clear = float(grasp[2]) + CLEARANCE
        new = target.copy()
        if tcp[2] < clear and np.linalg.norm(target[:2] - tcp[:2]) > SLIDE:
            new[:2] = tcp[:2]  # down at the part: no push
        elif np.linalg.norm(target[:2] - grasp[:2]) > REACH:
            new[2] = max(float(target[2]), clear)  # not over the part: stay clear of it
        if np.allclose(new, target):
            return action, None
        out = a.copy()
        out[:3] = np.clip(self.workspace.to_normalized(new), -1.0, 1.0)
        return out, DESCENT

    def carry(self, action: np.ndarray, place: np.ndarray, phase: int, held: bool) -> tuple[np.ndarray, str | None]:
        """(the action to run, CARRY if it was rewritten, else None); `place` is where the cup stands when the part it
        holds rests at its goal (m). Only while the part is held in the transport or the release; an action the decision
        step will refuse passes unchanged."""
        a = np.asarray(action, dtype=float)
        if not held or phase < Phase.TRANSPORT or a.shape != (ACT_DIM,) or not np.all(np.isfinite(a)):
            return action, None
        place = np.asarray(place, dtype=float)
        target = self.workspace.to_cartesian(np.clip(a[:3], -1.0, 1.0))
        clear = float(place[2]) + CARRY_CLEARANCE
        if target[2] >= clear or np.linalg.norm(target[:2] - place[:2]) <= self.place_reach:
            return action, None
        out = a.copy()
        out[:3] = np.clip(self.workspace.to_normalized(np.array([target[0], target[1], clear])), -1.0, 1.0)
        return out, CARRY
