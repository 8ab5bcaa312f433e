"""The annotation page beside on-cell learning (`mrguide deploy --cycles N --learn RUN_DIR --annotate PORT`): a person
presses Intervene, the runtime takes it up at the next episode's start (`deploy.interventions`: the safe point), the
person marks the pick and the place through the broker exactly as training's live expert asks them, and the episode
is played by the expert training builds from a person's marks (`GuidedExpert` with `marks = "pick_place"`, the
training run's [guidance]: Eq. 13's bound, the phase waypoints, the searches), acting through the runtime.

The page and the broker are the live training's (`AnnotationServer`, `AnnotationBroker`, `LiveExpert`); the requests
show the cell as the runtime senses it (the drives' joints, the part from the pose source, corrected as the runtime
uses it; its orientation upright: the pose sources give positions). Every accepted mark is appended to
RUN_DIR/on-cell/annotations.jsonl before it is used and acknowledged then. A request that is skipped or not answered
within the timeout leaves the episode to the policy.

Each intervention's expert is new: it follows that intervention's two marks (bounded by Eq. 13 around the training
run's reference) and what its own searches find, never an earlier intervention's marks — the part or the cell's
registration may have changed, and a person's correction outranks them. Nothing is asked while the arm moves: where
the demonstration would ask for a mark again (its search found nothing around the waypoint), it gets the person's
mark once more and searches again.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from mrguide.annotation.broker import AnnotationBroker
from mrguide.annotation.live import LiveExpert, LiveOptions, hello_fields
from mrguide.annotation.server import AnnotationServer
from mrguide.deploy.interventions import CellStart
from mrguide.policies.annotations import Annotation, AnnotationCache
from mrguide.policies.guidance import REFERENCE_POSES, GuidanceConfig
from mrguide.policies.guided_expert import GuidedExpert
from mrguide.robot import RobotSpec
from mrguide.task import (
    OBS_PROGRESS,
    PHASES,
    PICK_PHASE,
    PLACE_PHASE,
    TaskConfig,
    mark_phase,
    phase_from_progress,
    progress,
)

log = logging.getLogger(__name__)

#: The part's orientation a request shows (x, y, z, w): upright, as the task model has it.
UPRIGHT = np.array([0.0, 0.0, 0.0, 1.0])


class MarksSource:
    """An intervention's two marks as an expert source: the pick up to the lift, the place from the transport on."""

    def __init__(self, pick: Annotation, place: Annotation):
        self.marks: dict[int, Annotation] = {PICK_PHASE: pick, PLACE_PHASE: place}

    def annotate(self, obs: np.ndarray, previous: Annotation | None = None) -> Annotation:
        return self.marks[mark_phase(phase_from_progress(obs[OBS_PROGRESS]))]


class CellDemonstration:
    """The expert of one intervention, as the runtime's policy for its episode (`deploy.interventions`)."""

    def __init__(self, expert: GuidedExpert):
        self.expert = expert

    def act(self, obs: np.ndarray) -> np.ndarray | None:
        step = self.expert.action(np.asarray(obs))
        return None if step is None else step.executed


class CellInterventions:
    """The annotation server and broker of a learning session, and the experts its interventions build (`close()`)."""

    def __init__(
        self, options: LiveOptions, spec: RobotSpec, task: TaskConfig, guidance: GuidanceConfig, out: Path, seed: int
    ):
        """`guidance`: the training run's (how marks become an expert); `out`: where annotations.jsonl goes."""
        self.spec, self.task, self.guidance, self.seed = spec, task, guidance, seed
        self.broker = AnnotationBroker(spec.workspace, hello_fields(spec, task, None, "skip"), options.claim_timeout_s)
        self.server = AnnotationServer(
            self.broker, spec, options.host, options.port, options.cert, options.key, options.token
        )
        self._start: CellStart | None = None
        self.live = LiveExpert(self.broker, self._scene, task, "skip", options.timeout_s)
        self.record = AnnotationCache(guidance.cache_tolerance, out / "annotations.jsonl")
        self.url = self.server.start()

    def _scene(self) -> tuple[np.ndarray, np.ndarray]:
        assert self._start is not None, "asked outside an intervention"
        return self._start.joints, UPRIGHT

    def requested(self) -> str | None:
        return self.broker.take_intervention()

    def demonstration(self, episode: int, start: CellStart) -> tuple[CellDemonstration | None, dict[str, Any]]:
        """Ask for the pick and the place mark with the cell as it is at `start`; the expert from them, or None with
        why (a skip, a timeout) and what the run log keeps."""
        self._start = start
        given: list[Annotation] = []
        marks: list[dict[str, Any]] = []
        for kind in (PICK_PHASE, PLACE_PHASE):
            ask = start.obs.copy()  # the request names the mark's phase, as training's `_plan_mark` asks it
            ask[OBS_PROGRESS] = progress(kind)
            ann = self.live.annotate(ask)
            if ann is None:
                return None, {"marks": marks, "reason": self.live.unanswered}
            self.record.insert(ask, ann)  # on disk (fsync'd) before it is used
            self.live.recorded(ann)
            given.append(ann)
            marks.append({"phase": PHASES[kind], "target": ann.target, "vacuum": ann.grip > 0, **ann.info})
        log.info("episode %d: demonstrated from the marks of %s", episode, marks[0].get("client_id"))
        return CellDemonstration(self._expert(*given)), {"marks": marks}

    def _expert(self, pick: Annotation, place: Annotation) -> GuidedExpert:
        """Training's expert of a person's pick and place marks, with the training run's [guidance]; the cell's
        observations already hold the part as the cell perceives it (no simulated pose error on top)."""
        g = self.guidance
        return GuidedExpert(
            MarksSource(pick, place),
            REFERENCE_POSES[g.reference](self.task),
            AnnotationCache(g.cache_tolerance),
            g.delta,
            self.task,
            self.spec.workspace.to_normalized,
            reask_after=0,  # nothing is asked while the arm moves: the searches go on around the marks
            seed=self.seed,
            marks="pick_place",
            mark_precision=g.mark_precision,
        )

    def publish(self, **status: Any) -> None:
        self.broker.publish_status(**status)

    def close(self) -> None:
        """End an outstanding request (as `shutdown`) and stop serving."""
        self.broker.close()
        self.server.stop()
