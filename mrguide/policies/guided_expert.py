"""The expert side of guided training: annotations from a source, cached, re-marked when unreached,
bounded by Eq. 13, optionally perturbed, and turned into normalized actions."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from mrguide.config import ConfigError
from mrguide.policies.annotations import AnnotationCache
from mrguide.policies.choices import ExpertSourceName, MarksMode
from mrguide.policies.experts import ANNOTATOR_SEED_OFFSET, ExpertSource, FileExpert, OracleExpert, SimulatedAnnotator
from mrguide.policies.guidance import GuidanceConfig, ReferencePose, bounded_projection
from mrguide.policies.mark_fusion import KINDS, MarkFusion, anchor
from mrguide.task import (
    G_REQUIRED,
    OBS_PROGRESS,
    TaskConfig,
    annotation_action,
    mark_phase,
    phase_from_progress,
    progress,
    waypoint_from_mark,
)
from mrguide.twin.env import PickPlaceEnv

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


class GuidedExpert:
    """Expert actions for the learner: cache → source (counted) → bounded projection → normalized action.

    With `marks = "phases"` (the paper's protocol) every phase's waypoint is a mark of its own, bounded by Eq. 13
    around `reference`. With `marks = "pick_place"` a demonstration needs two marks, the pick (grasp point) and
    the place (set-down point): every mark is fused with all earlier ones (`MarkFusion`), the fused mark bounded
    by Eq. 13 around the reference's pick or place point, and the five phase waypoints follow from it
    (`waypoint_from_mark`).

    A waypoint the arm has followed for `reask_after` consecutive expert steps without the phase advancing was
    not reachable as marked (noise, a slip of the hand): it is asked again, as a person watching the arm would
    re-mark it, and the new mark supersedes the old one in the cache.
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
    ):
        """`counts` is what the expert counts into (default: counts of its own)."""
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
        self._streak = (
            -1,
            0,
        )  # phases: (cache index in use, consecutive expert steps on it); pick_place: (phase, steps)
        self._plan: dict[int, tuple[int, np.ndarray]] = {}  # pick_place: mark phase → (cache index, fused mark in m)

    def begin_demonstration(self) -> None:
        self._streak = (-1, 0)
        self._plan = {}

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
        target = bounded_projection(ann.target, self.reference.reference(obs), self.delta)
        self.counts.projected += int(not np.allclose(target, ann.target))
        return target, ann.grip

    def _pick_place_waypoint(self, obs: np.ndarray) -> tuple[np.ndarray, float] | None:
        """Two marks per demonstration: the phase's waypoint from the fused pick or place mark, fixed for the
        demonstration when first needed (so the lift rises above where the cup went down)."""
        phase = phase_from_progress(obs[OBS_PROGRESS])
        kind = mark_phase(phase)
        steps = self._streak[1] + 1 if self._streak[0] == phase else 1
        ask_obs = obs.copy()  # the request names the mark's phase: the page asks for the grasp or set-down point
        ask_obs[OBS_PROGRESS] = progress(kind)
        planned = self._plan.get(kind)
        due = planned is not None and self.reask_after and steps > self.reask_after
        if planned is None or due:
            hit = self.cache.lookup(ask_obs) if planned is None else None
            if hit is not None:
                self.counts.reused += 1
                index = hit.index
            else:
                self.counts.remarks += int(bool(due))
                asked = self._ask(ask_obs, planned[0] if planned else None)
                if asked is None:
                    return None
                index = asked
                steps = 1
            fused = self.fusion.point(kind, anchor(kind, ask_obs))
            bounded = bounded_projection(fused, self.reference.reference(ask_obs), self.delta)
            self.counts.projected += int(not np.allclose(bounded, fused))
            self._plan[kind] = (index, bounded)
        else:
            self.counts.reused += 1
        self._streak = (phase, steps)
        return waypoint_from_mark(phase, self._plan[kind][1], self.task), float(G_REQUIRED[phase])

    def _ask(self, obs: np.ndarray, previous: int | None) -> int | None:
        """Ask the source (a re-mark of cache record `previous` if given); the new record's index, or None."""
        ann = self.source.annotate(obs, self.cache.get(previous) if previous is not None else None)
        self.counts.asked += 1
        if ann is None:
            return None
        index = self.cache.insert(obs, ann, supersedes=previous)  # on disk (fsync'd) when this returns
        recorded = getattr(self.source, "recorded", None)
        if recorded is not None:
            recorded(ann)
        if self.marks == "pick_place":
            kind = phase_from_progress(obs[OBS_PROGRESS])
            self.fusion.add(kind, anchor(kind, obs), ann.target)
        self.reference.observe(obs, ann)
        return index

    def reload(self) -> None:
        """Rebuild the fused marks and the reference from the cache (after it was loaded on resume), in the order the
        marks were made."""
        self.fusion = MarkFusion()
        for obs, ann in self.cache.history():
            kind = phase_from_progress(obs[OBS_PROGRESS])
            if self.marks == "pick_place" and kind in KINDS:
                self.fusion.add(kind, anchor(kind, obs), ann.target)
            self.reference.observe(obs, ann)


#: The in-process expert source of each guidance.source, built from (guidance, env, training seed). "live" is not
#: among them: a person is attached by `mrguide train --expert live` (the trainer's `source_factory`).
IN_PROCESS_SOURCES: dict[ExpertSourceName, Callable[[GuidanceConfig, PickPlaceEnv, int], ExpertSource]] = {
    "oracle": lambda g, env, seed: OracleExpert(env.task_cfg),
    "annotator": lambda g, env, seed: SimulatedAnnotator(
        env.task_cfg, g.noise, env.workspace, seed=seed + ANNOTATOR_SEED_OFFSET
    ),
    "file": lambda g, env, seed: FileExpert(g.annotation_file, g.cache_tolerance),
}


def make_expert_source(g: GuidanceConfig, env: PickPlaceEnv, seed: int) -> ExpertSource:
    """The configured in-process expert source (a live person is attached by `mrguide train --expert live`)."""
    build = IN_PROCESS_SOURCES.get(g.source)
    if build is None:
        raise ConfigError(f"guidance.source = {g.source!r} needs a person: run `mrguide train --expert live`")
    return build(g, env, seed)
