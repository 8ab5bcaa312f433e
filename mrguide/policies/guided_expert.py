"""The expert side of guided training: annotations from a source, cached, re-marked when unreached,
bounded by Eq. 13, optionally perturbed, and turned into normalized actions.

The expert sees the part where the cell would: through the configured pose error, its looks averaged while the part
stands still (`PerceivedPart`), never the twin's exact pose, wherever the part's pose enters the expert path (Eq. 13's
reference, the marks' anchors, the seals' offsets). A person marks the real part: the source is asked with the
observation as it is."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import NamedTuple

import numpy as np

from mrguide.config import ConfigError
from mrguide.grasp_margin import steady_grasp
from mrguide.parts import part_named
from mrguide.policies.annotations import Annotation, AnnotationCache
from mrguide.policies.choices import EXPERT_SOURCES, MarksMode
from mrguide.policies.experts import ANNOTATOR_SEED_OFFSET, ExpertSource, FileExpert, OracleExpert, SimulatedAnnotator
from mrguide.policies.guidance import GuidanceConfig, PoseError, ReferencePose, bounded_projection
from mrguide.policies.mark_fusion import INTENT_RADIUS, KINDS, MarkFusion, anchor
from mrguide.policies.perceived_part import PerceivedPart
from mrguide.policies.pick_place_demo import PickPlaceDemo
from mrguide.registries import register
from mrguide.task import (
    G_REQUIRED,
    OBS_PROGRESS,
    PICK_PHASE,
    PLACE_PHASE,
    Phase,
    TaskConfig,
    annotation_action,
    mark_phase,
    phase_from_progress,
    progress,
)
from mrguide.twin.env import PickPlaceEnv

log = logging.getLogger(__name__)

ACTION_NOISE_SEED_OFFSET = 104_729  # the expert-action noise of training seed s draws from RNG seed s + this


class ExpertStep(NamedTuple):
    """What the expert does at one step: the action that drives the arm and the one stored with ζ = 1.

    They differ only under `guidance.action_noise` (noisy labels, clean execution).
    """

    executed: np.ndarray
    stored: np.ndarray


@dataclass
class ExpertCounts:
    """What the guided expert counted (the trainer's `TrainerCounters` extends it, so one object holds all)."""

    asked: int = 0  # annotations asked of the source
    reused: int = 0  # expert steps that reused a cached annotation (or a planned mark)
    projected: int = 0  # annotations moved onto the Δ-sphere (Eq. 13)
    remarks: int = 0  # waypoints asked again because the arm did not reach them
    probes: int = 0  # targets a demonstration's search tried beyond a waypoint that did not complete its phase
    measured: int = 0  # seals and placements the cell measured (recorded as pick and place measurements)
    corrections: int = 0  # of the marks asked, those correcting what was taught ("here" after Intervene)


class GuidedExpert:
    """Expert actions for the learner: cache → source (counted) → bounded projection → normalized action.

    With `marks = "phases"` (the paper's protocol) every phase's waypoint is a mark of its own, bounded by Eq. 13
    around `reference`. With `marks = "pick_place"` a demonstration needs two marks, the pick (grasp point) and
    the place (set-down point): every mark is fused with all earlier ones (`MarkFusion`), the fused mark bounded
    by Eq. 13 around the reference's pick or place point, and the five phase waypoints follow from it
    (`waypoint_from_mark`).

    A waypoint the arm has followed for `reask_after` consecutive expert steps without the phase advancing was
    not reachable as marked (noise, a slip of the hand): it is asked again, as a person watching the arm would
    re-mark it, and the new mark supersedes the old one in the cache. Where the waypoint came from what the cell
    measured and the search around it found nothing, the measurement was wrong (a part the cup dragged before it
    sealed): it is withdrawn, and the marks, the new one with them, stand for the point again.
    """

    def __init__(
        self,
        source: ExpertSource,
        reference: ReferencePose,
        cache: AnnotationCache,
        delta: float,
        task: TaskConfig,
        to_normalized,
        reask_after: int = 0,
        action_noise: float = 0.0,
        seed: int = 0,
        marks: MarksMode = "pick_place",
        counts: ExpertCounts | None = None,
        pose_error: PoseError | None = None,
        mark_precision: float = 0.0,
    ):
        """`counts` is what the expert counts into (default: counts of its own). A kind of mark whose fused value is
        known to within `mark_precision` (m, per axis) is not asked again (`MarkFusion.settled`)."""
        self.source, self.reference, self.cache = source, reference, cache
        self.action_noise = action_noise
        self.rng = np.random.default_rng(seed + ACTION_NOISE_SEED_OFFSET)  # draws only when action_noise > 0
        self.delta = delta
        self.task = task
        self.to_normalized = to_normalized
        self.reask_after = reask_after
        self.marks = marks
        self.fusion = MarkFusion()
        self.counts = counts if counts is not None else ExpertCounts()
        self.perceived = PerceivedPart(pose_error or PoseError(), seed)
        self.mark_precision = mark_precision
        self.demo = PickPlaceDemo(task)
        self._person = False  # a person stepped in for this demonstration: every mark is asked of them
        self._corrected = False  # a person corrected what they had taught, since the trainer last looked
        self._streak = (
            -1,
            0,
        )  # phases: (cache index in use, consecutive expert steps on it); pick_place: (phase, steps)
        #: pick_place: mark phase → (cache index or None, fused mark in m, the perceived anchor it was fused at)
        self._plan: dict[int, tuple[int | None, np.ndarray, np.ndarray]] = {}

    def begin_demonstration(self, person: bool = False) -> None:
        """A new demonstration; `person`: a person stepped in for it, and is asked every mark, settled or not (they
        stepped in to say something: a correction, "not there — here", is an answer with `here`)."""
        self._person = person
        self._streak = (-1, 0)
        self._plan = {}
        self.perceived.new_part()
        self.demo = PickPlaceDemo(self.task, self.fusion.intent(PICK_PHASE))

    def retasked(self) -> TaskConfig | None:
        """The task with the grasp taught so far (`taught_grasp`) when it changed since the last look, else None. The
        expert, its reference and its demonstration follow it; the caller hands it to the env, whose reward does."""
        grasp = self.taught_grasp()
        if grasp == self.task.grasp:
            return None
        self.task = self.demo.task = self.reference.task = replace(self.task, grasp=grasp)
        return self.task

    def corrected(self) -> bool:
        """Whether a person corrected what they had taught since the last call: the demonstrations made before it aimed
        elsewhere (the trainer forgets them)."""
        was, self._corrected = self._corrected, False
        return was

    def taught_grasp(self) -> tuple[float, float, float] | None:
        """Where the cup grips the part (m, in the part's frame as the cell sees it) as a person taught it and the
        cell refined it (`_steady_pick`), for the task's targets (`TaskConfig.grasp`); None under the centre prior.
        Its height is the part's top face there (`Part.surface_height`), where the person's mark or the cup's press
        does not tell it; over no face, the estimate's own."""
        pick = self._steady_pick()
        if pick is None:
            return None
        part = part_named(self.task.part)
        z = part.surface_height(pick[:2])
        low, high = part.bounds
        grasp = np.clip([pick[0], pick[1], pick[2] if z is None else z], low, high)
        return (float(grasp[0]), float(grasp[1]), float(grasp[2]))

    def _steady_pick(self) -> np.ndarray | None:
        """The taught pick offset (the fusion's estimate) moved the least it must, within INTENT_RADIUS, to where a
        seal has room on the part's face (`grasp_margin.steady_grasp`); None under the centre prior."""
        if not self.fusion.taught[PICK_PHASE]:
            return None
        est = self.fusion.estimate(PICK_PHASE)
        assert est is not None
        xy = steady_grasp(part_named(self.task.part), est[:2], INTENT_RADIUS)
        return np.r_[xy, est[2]]

    def end_demonstration(self, success: bool) -> None:
        """A successful demonstration measures the place (pick_place marks): the height at which its descent set the
        part down, over the goal. The cell knows where the goal is, and the success rule asks the TCP to open within
        ε of the goal's top; a success anywhere within ε would otherwise keep the place where it happened to
        succeed — up to ε beside the goal, where every wobble of the policy that clones it fails."""
        if success and self.demo.released is not None and PLACE_PHASE in self._plan:
            goal = self._plan[PLACE_PHASE][2]
            self._measured(PLACE_PHASE, np.r_[goal[:2] + self.task.grasp_offset[:2], self.demo.released[2]])

    def annotation_in_use(self, obs: np.ndarray) -> int | None:
        """The annotation cache record the last `action(obs)` followed (its index in annotations.jsonl), or None."""
        if self.marks == "pick_place":
            planned = self._plan.get(mark_phase(phase_from_progress(obs[OBS_PROGRESS])))
            return planned[0] if planned is not None else None
        return self._streak[0] if self._streak[0] >= 0 else None

    def action(self, obs: np.ndarray) -> ExpertStep | None:
        """The expert's normalized action for `obs` (executed and stored), or None when nobody annotated."""
        waypoint = self._pick_place_waypoint(obs) if self.marks == "pick_place" else self._phase_waypoint(obs)
        if waypoint is None:
            return None
        target, grip = waypoint
        clean = annotation_action(obs, target, grip, self.task, self.to_normalized)
        if self.marks == "pick_place" and self.demo.phase == Phase.RELEASE:
            clean[3] = -1.0 if self.demo.opens_now(obs, target, clean[3] < 0) else 1.0
        if self.action_noise == 0:
            return ExpertStep(clean, clean)
        noisy = clean.copy()  # the label's motion is perturbed; the vacuum command stays the annotation's
        noisy[:3] = self.to_normalized(target + self.rng.normal(0.0, self.action_noise, 3))
        return ExpertStep(clean, noisy)

    def _phase_waypoint(self, obs: np.ndarray) -> tuple[np.ndarray, float] | None:
        """The paper's protocol: this phase's own mark, bounded by Eq. 13 around the reference."""
        hit = self.cache.lookup(obs)
        if hit is None or (self.reask_after and self._streak == (hit.index, self.reask_after)):
            self.counts.remarks += int(hit is not None)
            index = self._ask(obs, hit.index if hit else None)
            if index is None:
                return None
            self._streak = (index, 1)
        else:
            self.counts.reused += 1
            index = hit.index
            self._streak = (index, self._streak[1] + 1 if self._streak[0] == index else 1)
        ann = self.cache.get(index)
        target = bounded_projection(ann.target, self.reference.reference(self.perceived(obs)), self.delta)
        self.counts.projected += int(not np.allclose(target, ann.target))
        return target, ann.grip

    def _pick_place_waypoint(self, obs: np.ndarray) -> tuple[np.ndarray, float] | None:
        """Two marks per demonstration: the phase's waypoint from the fused pick or place point, fixed for the
        demonstration when first needed, searched around and corrected by the demonstration (`PickPlaceDemo`)."""
        phase = phase_from_progress(obs[OBS_PROGRESS])
        kind = mark_phase(phase)
        if not self.demo.started or phase != self.demo.phase:
            sealed = self.demo.enter(phase, obs)
            if sealed is not None:
                self._measured(PICK_PHASE, sealed)
        seen = self.perceived.at_decision(obs, phase)
        if phase == Phase.LIFT:
            self.demo.carried(seen)
        steps = self._streak[1] + 1 if self._streak[0] == phase else 1
        planned = self._plan.get(kind)
        due = planned is not None and self.demo.search is None and self.reask_after and steps > self.reask_after
        if planned is None or due:
            if not self._plan_mark(obs, kind, None if planned is None else planned[0], seen):
                return None
            steps = 1
        else:
            self.counts.reused += 1
            self._follow_still_part(kind, phase, seen)
        self._streak = (phase, steps)
        probe = self.demo.probe
        target = self.demo.next_target(self._plan[kind][1], seen)
        if target is None:  # nothing around the waypoint completes the phase: the person marks again
            self.counts.remarks += 1
            if withdrawn := self.fusion.withdraw(kind):
                log.info(
                    "the search found nothing around %d measurement(s) of mark phase %d: withdrawn", withdrawn, kind
                )
            if not self._plan_mark(obs, kind, self._plan[kind][0], seen, force=True):
                return None
            self.demo.restart_phase()
            target = self.demo.next_target(self._plan[kind][1], seen)
            assert target is not None
        elif self.demo.probe != probe:
            self.counts.probes += 1
        return target, float(G_REQUIRED[phase])

    def _follow_still_part(self, kind: int, phase: int, seen: np.ndarray) -> None:
        """The pick planned against an earlier estimate of the part's centre moves with the estimate as looks add to
        it (the seal is then measured against the estimate the cup went down on)."""
        if kind != PICK_PHASE or phase > Phase.GRASP or self.perceived.exact:
            return
        index, point, at = self._plan[kind]
        now = anchor(kind, seen)
        self._plan[kind] = (index, point + (now - at), now)

    def _plan_mark(
        self, obs: np.ndarray, kind: int, previous: int | None, seen: np.ndarray, force: bool = False
    ) -> bool:
        """Fix this demonstration's fused `kind` mark: from a cached mark for this observation, from the fusion alone
        once it is settled, or from a fresh mark (a re-mark of record `previous`); False when nobody answered. `seen`:
        the decision's observation with the part where the cell sees it (`PerceivedPart.at_decision`)."""
        ask_obs = obs.copy()  # the request names the mark's phase: the page asks for the grasp or set-down point
        ask_obs[OBS_PROGRESS] = progress(kind)
        hit = self.cache.lookup(ask_obs) if previous is None else None
        index: int | None
        if hit is not None:
            self.counts.reused += 1
            index = hit.index
        elif not force and previous is None and not self._person and self.fusion.settled(kind, self.mark_precision):
            self.counts.reused += 1
            index = None
        else:
            self.counts.remarks += int(previous is not None and not force)
            index = self._ask(ask_obs, previous)
            if index is None:
                return False
        seen = seen.copy()
        seen[OBS_PROGRESS] = ask_obs[OBS_PROGRESS]
        at = anchor(kind, seen)
        steady = self._steady_pick() if kind == PICK_PHASE else None
        fused = self.fusion.point(kind, at) if steady is None else at + steady
        bounded = bounded_projection(fused, self.reference.reference(seen), self.delta)
        self.counts.projected += int(not np.allclose(bounded, fused))
        self._plan[kind] = (index, bounded, at)
        return True

    def _measured(self, kind: int, point: np.ndarray) -> None:
        """The cell found the pick (a seal) or the place (a success) at `point`, planned from this demonstration's
        perceived anchor."""
        self.fusion.add_measurement(kind, self._plan[kind][2], point)
        self.counts.measured += 1

    def _ask(self, obs: np.ndarray, previous: int | None) -> int | None:
        """Ask the source (a re-mark of cache record `previous` if given); the new record's index, or None. The source
        is shown the part where the cell sees it (a person's page draws it there); the record keeps `obs`."""
        shown = obs if self.perceived.exact else self.perceived(obs).astype(np.asarray(obs).dtype)  # an observation
        ann = self.source.annotate(shown, self.cache.get(previous) if previous is not None else None)
        self.counts.asked += 1
        if ann is None:
            return None
        if ann.here and self._person:  # a person who stepped in and says "here" corrects what was taught
            ann.info["correction"] = True
            self.counts.corrections += 1
            self._corrected = True
        index = self.cache.insert(obs, ann, supersedes=previous)  # on disk (fsync'd) when this returns
        recorded = getattr(self.source, "recorded", None)
        if recorded is not None:
            recorded(ann)
        seen = self.perceived(obs)
        if self.marks == "pick_place":
            self._fuse(phase_from_progress(obs[OBS_PROGRESS]), seen, ann)
        self.reference.observe(seen, ann)
        return index

    def _fuse(self, kind: int, seen: np.ndarray, ann: Annotation) -> None:
        """Fuse a pick or place mark made with the part and goal at `seen`: taught where the person said "here" (a
        correction where they had stepped in: the record says so)."""
        if ann.here:
            self.fusion.teach(kind, anchor(kind, seen), ann.target, bool(ann.info.get("correction")))
            if kind == PICK_PHASE:
                self.demo.intent = self.fusion.intent(PICK_PHASE)[:2]  # type: ignore[index]
        else:
            self.fusion.add(kind, anchor(kind, seen), ann.target)

    def reload(self) -> None:
        """Rebuild the fused marks and the reference from the cache (after it was loaded on resume), in the order the
        marks were made."""
        measured, self.fusion = self.fusion.measured, MarkFusion()
        for obs, ann in self.cache.history():
            seen = self.perceived(obs)
            kind = phase_from_progress(obs[OBS_PROGRESS])
            if self.marks == "pick_place" and kind in KINDS:
                self._fuse(kind, seen, ann)
            self.reference.observe(seen, ann)
        self.fusion.measured = measured  # not in the annotation file: the checkpoint restores them (Trainer)


#: (guidance, env, training seed) → an expert source.
SourceFactory = Callable[[GuidanceConfig, PickPlaceEnv, int], ExpertSource]
#: The in-process expert source of each guidance.source (`register_expert_source`). "live" is not among them: a
#: person is attached by `mrguide train --expert live` (the trainer's `source_factory`).
IN_PROCESS_SOURCES: dict[str, SourceFactory] = {}


def register_expert_source(name: str, factory: SourceFactory) -> None:
    """Make `guidance.source = NAME` build its marks' source with `factory`; ValueError if the name is taken."""
    if name == "live":  # the person's source, attached by the trainer: in the names, never in the table
        raise ValueError(f"expert source {name!r} is registered already")
    register(IN_PROCESS_SOURCES, name, factory, "expert source", EXPERT_SOURCES)


register_expert_source("oracle", lambda g, env, seed: OracleExpert(env.task_cfg))
register_expert_source(
    "annotator",
    lambda g, env, seed: SimulatedAnnotator(env.task_cfg, g.noise, env.workspace, seed=seed + ANNOTATOR_SEED_OFFSET),
)
register_expert_source("file", lambda g, env, seed: FileExpert(g.annotation_file, g.cache_tolerance))


def make_expert_source(g: GuidanceConfig, env: PickPlaceEnv, seed: int) -> ExpertSource:
    """The configured in-process expert source (a live person is attached by `mrguide train --expert live`)."""
    build = IN_PROCESS_SOURCES.get(g.source)
    if build is None:
        raise ConfigError(f"guidance.source = {g.source!r} needs a person: run `mrguide train --expert live`")
    return build(g, env, seed)
