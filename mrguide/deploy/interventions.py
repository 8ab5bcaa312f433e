"""A person stepping in during on-cell learning (HIL-SERL's interventions), the actor's side. numpy only: the
annotation page, its broker and the expert a person's marks build live above deploy and are injected
(`mrguide deploy --cycles N --learn RUN_DIR --annotate PORT`).

**The safe point is the start of an episode.** A person's "Intervene" is taken up at the start of the next episode
(an attempt of a cycle): the arm stands where the cycle runner put it (home, or risen clear of the part it just
placed), carries no part, the vacuum is off and the stall watchdog is off, and the learner's exchange happens at the
same point. Nothing waits for a person while the arm moves or holds a part: both marks (where the cup touches the
part, where the part is set down) are asked there, before the first decision, with the scene as the runtime senses it.
The episode is then played by the expert built from those marks, through the same runtime and every rule of it (the
workspace clamp, IK and joint limits, the lift rules, the hold in transit, the seal search, the supervisor); its
decisions are tapped as expert data (ζ = 1). A request that is skipped or times out, or a part the pose source
cannot see at that point, leaves the episode to the policy; the run log says so.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from mrguide.deploy.object_tracking import ObjectTracker
from mrguide.drivers.interface import CobotInterface
from mrguide.motion.decision import DecisionStep
from mrguide.pose_source import PoseUnavailable

log = logging.getLogger(__name__)

Write = Callable[..., None]  # RunLog.write


@dataclass(frozen=True)
class CellStart:
    """What the cell senses at an episode's start, before its first decision: what a person marks on."""

    joints: np.ndarray  # rad, the drives' feedback
    obs: np.ndarray  # the observation the first decision is made from (φ = 0): TCP, g, the part as the runtime sees it


def sense_start(cobot: CobotInterface, decision: DecisionStep, objects: ObjectTracker, goal: np.ndarray) -> CellStart:
    """The cell's state as the runtime's first decision of an episode toward `goal` will sense it: the joints and
    the vacuum from the drives, the part from the pose source corrected as the runtime corrects it (`objects`);
    PoseUnavailable if the source has no pose."""
    js, vac = cobot.joint_state(), cobot.vacuum_state()
    obs = decision.observe(decision.tcp(js.positions), 1 if vac.vacuum_on else -1, objects.first_look(), goal)
    return CellStart(np.array(js.positions, dtype=float), obs)


class Demonstration(Protocol):
    """The expert a person's marks built, for one episode: obs → action, or None when it has nothing to do."""

    def act(self, obs: np.ndarray) -> np.ndarray | None: ...


class Interventions(Protocol):
    """Where a person steps in (the annotation page's broker) and what their marks build."""

    def requested(self) -> str | None:
        """Who asked to step in since the last call (forgotten once returned), or None."""
        ...

    def demonstration(self, episode: int, start: CellStart) -> tuple[Demonstration | None, dict[str, Any]]:
        """Ask for the marks with the cell as it is at `start`: the expert that plays the episode (None: nobody
        answered, the policy plays it) and what the run log keeps (the marks, who gave them, why none)."""
        ...

    def publish(self, **status: Any) -> None:
        """Show the cell's status on the page."""
        ...


@dataclass
class InterventionCounts:
    """Interventions asked for, those played by a person's expert, those left to the policy (no answer, no pose)."""

    asked: int = 0
    played: int = 0
    fell_back: int = 0

    def as_dict(self) -> dict[str, int]:
        return {
            "interventions": self.played,
            "interventions_asked": self.asked,
            "interventions_fell_back": self.fell_back,
        }


def take_intervention(
    interventions: Interventions, counts: InterventionCounts, episode: int, sense: Callable[[], CellStart], write: Write
) -> Demonstration | None:
    """At an episode's start: if a person asked to step in, the expert from their marks (the intervention and its
    marks written to the run log as `intervention`); None: the policy plays the episode."""
    who = interventions.requested()
    if who is None:
        return None
    counts.asked += 1
    at = time.strftime("%Y-%m-%dT%H:%M:%S%z")
    try:
        expert, record = interventions.demonstration(episode, sense())
    except PoseUnavailable as exc:
        expert, record = None, {"marks": [], "reason": f"no pose of the part to mark on: {exc}"}
    played_by = "policy" if expert is None else "expert"
    counts.played += expert is not None
    counts.fell_back += expert is None
    write("intervention", episode=episode, client_id=who, at=at, played_by=played_by, **record)
    if expert is None:
        log.warning("intervention of %s in episode %d: the policy plays it (%s)", who, episode, record.get("reason"))
    return expert
