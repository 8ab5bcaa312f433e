"""What a training run counts and writes: its counters (saved whole in the checkpoint), the columns of metrics.csv
and eval.csv, and the sinks that receive the same rows (e.g. TensorBoard)."""

from __future__ import annotations

import csv
import dataclasses
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import dacite

from mrguide.policies.guided_expert import ExpertCounts

#: Update statistics in metrics.csv, each the mean over the updates since the previous row (see DDPG.update):
#: critic loss, actor loss, mean and max Q_φ1(s, a) of the batch, BC loss (DDPG), temperature (SAC). Empty in a row with no update
#: since the previous one (before learning_starts; the agent row of a triggered episode, which follows
#: its expert row).
UPDATE_FIELDS = ("critic_loss", "actor_loss", "q_mean", "q_max", "bc_loss", "temperature")
METRIC_FIELDS = (
    "step",
    "episode",
    "kind",
    "return",
    "success",
    "outcome",
    "length",
    "triggered",
    "lambda",
    "expert_ratio",
    "asked",
    "reused",
    "remarks",
    "skipped",
    "wall_s",
    *UPDATE_FIELDS,
    "intervened",
)  # new columns go at the end
EVAL_FIELDS = ("step", "success_rate", "mean_return")


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

    def restore(self, saved: dict[str, Any]) -> None:
        """Set every counter from a checkpoint's `counters`, in place (the expert holds this object). Each must be
        there, with its type, and nothing else (KeyError or a dacite error otherwise)."""
        missing = [f.name for f in dataclasses.fields(self) if f.name not in saved]
        if missing:
            raise KeyError(f"counters {', '.join(missing)}")
        loaded = dacite.from_dict(type(self), saved, dacite.Config(strict=True, cast=[float]))
        for f in dataclasses.fields(self):
            setattr(self, f.name, getattr(loaded, f.name))


class MetricSink(Protocol):
    """Receives what the trainer writes to metrics.csv and eval.csv, as it writes it (e.g. TensorBoardLog)."""

    def row(self, row: dict) -> None: ...

    def evaluation(self, res: dict) -> None: ...


def append_csv(path: Path, fields: tuple[str, ...], row: dict) -> None:
    """Append one row (with a header when the file is new); each row is on disk when this returns."""
    new = not path.exists()
    with path.open("a", newline="") as fh:
        w = csv.DictWriter(fh, fields)
        if new:
            w.writeheader()
        w.writerow(row)


def replace_csv(path: Path, fields: tuple[str, ...], rows: list[dict]) -> None:
    """Rewrite `path` with `rows` (and a header) atomically: a temporary file beside it, fsync'd, then renamed over
    it. An interruption leaves the old file or the new one, never part of either."""
    tmp = path.with_name(path.name + ".tmp")
    try:
        with tmp.open("w", newline="") as fh:
            w = csv.DictWriter(fh, fields)
            w.writeheader()
            w.writerows(rows)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
