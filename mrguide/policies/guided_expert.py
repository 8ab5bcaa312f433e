"""The expert side of guided training: annotations from a source, cached, re-marked when unreached,
bounded by Eq. 13, optionally perturbed, and turned into normalized actions."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mrguide.config import ConfigError
from mrguide.policies.annotations import Annotation, AnnotationCache
from mrguide.policies.experts import ANNOTATOR_SEED_OFFSET, ExpertSource, FileExpert, OracleExpert, SimulatedAnnotator
from mrguide.policies.guidance import GuidanceConfig, ReferencePose, bounded_projection
from mrguide.task import TaskConfig, annotation_action
from mrguide.twin.env import PickPlaceEnv

ACTION_NOISE_SEED_OFFSET = 104_729  # the expert-action noise of training seed s draws from RNG seed s + this


class ExpertStep(NamedTuple):
    """What the expert does at one step: the action that drives the arm and the one stored with ζ = 1.

    They differ only under `guidance.action_noise_on = "stored"` (noisy labels, clean execution).
    """

    executed: np.ndarray
    stored: np.ndarray


class GuidedExpert:
    """Expert actions for the learner: cache → source (counted) → bounded projection → normalized action.

    A waypoint the arm has followed for `reask_after` consecutive expert steps without the phase
    advancing was not reachable as marked (noise, a slip of the hand): it is asked again, as a person
    watching the arm would re-mark it, and the new mark supersedes the old one in the cache.
    """

    def __init__(self, source: ExpertSource, reference: ReferencePose, cache: AnnotationCache, delta: float, task: TaskConfig,
                 to_normalized, reask_after: int = 0, action_noise: float = 0.0, noise_on: str = "executed", seed: int = 0,
                 noise_clip: bool = True):
        self.source, self.reference, self.cache = source, reference, cache
        self.action_noise, self.noise_on, self.noise_clip = action_noise, noise_on, noise_clip
        self.rng = np.random.default_rng(seed + ACTION_NOISE_SEED_OFFSET)  # draws only when action_noise > 0
        self.delta = delta
        self.task = task
        self.to_normalized = to_normalized
        self.reask_after = reask_after
        self.projected = 0  # annotations moved onto the Δ-sphere
        self.remarks = 0  # waypoints asked again because the arm did not reach them
        self._streak = (-1, 0)  # (cache index in use, consecutive expert steps on it)

    def begin_demonstration(self) -> None:
        self._streak = (-1, 0)

    def action(self, obs: np.ndarray) -> ExpertStep | None:
        """The expert's normalized action for `obs` (executed and stored), or None when nobody annotated."""
        hit = self.cache.lookup(obs)
        if hit is None:
            ann = self._ask(obs, None)
        elif self.reask_after and self._streak == (hit.index, self.reask_after):
            self.remarks += 1
            ann = self._ask(obs, hit)
        else:
            self.cache.reused += 1
            ann = hit.annotation
            self._streak = (hit.index, self._streak[1] + 1 if self._streak[0] == hit.index else 1)
        if ann is None:
            return None
        ref = self.reference.reference(obs)
        target = bounded_projection(ann.target, ref, self.delta)
        self.projected += int(not np.allclose(target, ann.target))
        clean = annotation_action(obs, target, ann.grip, self.task, self.to_normalized)
        if self.action_noise == 0:
            return ExpertStep(clean, clean)
        noisy = clean.copy()  # the motion is perturbed; the vacuum command stays the annotation's (decided on the clean waypoint)
        noisy[:3] = self.to_normalized(target + self.rng.normal(0.0, self.action_noise, 3))
        if self.noise_clip:
            noisy[:3] = np.clip(noisy[:3], -1.0, 1.0)
        return ExpertStep(noisy, noisy) if self.noise_on == "executed" else ExpertStep(clean, noisy)

    def _ask(self, obs: np.ndarray, previous) -> Annotation | None:
        ann = self.source.annotate(obs, previous.annotation if previous else None)
        self.cache.asked += 1
        if ann is None:
            return None
        index = self.cache.insert(obs, ann, supersedes=previous.index if previous else None)
        self.reference.observe(obs, ann)
        self._streak = (index, 1)
        return ann


def make_expert_source(g: GuidanceConfig, env: PickPlaceEnv, seed: int) -> ExpertSource:
    """The configured in-process expert source (a live person is attached by `mrguide train --expert live`)."""
    if g.source == "oracle":
        return OracleExpert(env.task_cfg)
    if g.source == "annotator":
        return SimulatedAnnotator(env.task_cfg, g.noise, env.workspace, seed=seed + ANNOTATOR_SEED_OFFSET)
    if g.source == "file":
        return FileExpert(g.annotation_file, g.cache_tolerance)
    raise ConfigError("guidance.source = 'live' needs a person: run `mrguide train --expert live`")
