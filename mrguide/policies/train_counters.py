"""Every counter of a training run, saved whole in its checkpoint."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import dacite

from mrguide.policies.guided_expert import ExpertCounts


@dataclass
class TrainerCounters(ExpertCounts):
    """Every counter of a run, saved in its checkpoint as one dict (`counters`) and restored as a whole: the guided
    expert's (the base class: the expert counts into this object) and the trainer's own."""

    step: int = 0  # environment steps, agent and expert
    episode: int = 0  # agent episodes
    interventions: int = 0  # demonstrations asked: threshold-triggered (Eq. 12) and person-triggered
    person_interventions: int = 0  # of those, a person stepped in ("Intervene" on the page)
    skipped: int = 0  # demonstrations dropped because nobody annotated
    last_ratio: float = 0.0  # the expert share of the last minibatch
    next_eval: int = 0  # the step at or after which the next evaluation runs
    evaluations: int = 0  # evaluations so far (they choose the evaluation seeds)
    wall_s: float = 0.0  # training wall time before this process (s); a checkpoint records it up to its writing
    update_s: float = 0.0  # wall time spent in updates, minibatch sampling included (s)

    def session_cost(self, decision_period: float) -> dict[str, float]:
        """What the run has cost the cell beside the marks asked (train_log's METRIC_FIELDS): probes, the robot's seconds
        (every decision for `decision_period` s), part resets (each agent episode, each demonstration put back), and
        which of the marks were a person's corrections."""
        robot_s = round(self.step * decision_period, 1)
        resets = self.episode + self.interventions
        return {"probes": self.probes, "robot_s": robot_s, "resets": resets, "corrections": self.corrections}

    def restore(self, saved: dict[str, Any]) -> None:
        """Set every counter from a checkpoint's `counters`, in place (the expert holds this object). Each must be
        there, with its type, and nothing else (KeyError or a dacite error otherwise)."""
        missing = [f.name for f in dataclasses.fields(self) if f.name not in saved]
        if missing:
            raise KeyError(f"counters {', '.join(missing)}")
        loaded = dacite.from_dict(type(self), saved, dacite.Config(strict=True, cast=[float]))
        for f in dataclasses.fields(self):
            setattr(self, f.name, getattr(loaded, f.name))
