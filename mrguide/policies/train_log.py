"""What a training run writes: the columns of metrics.csv and eval.csv, and the sinks that receive the same rows
(e.g. TensorBoard). Light to import: the TensorBoard log reads its columns without loading the trainer."""

from __future__ import annotations

import csv
import os
from pathlib import Path
from typing import Protocol

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
    "probes",
    "robot_s",
    "resets",
    "corrections",
)  # new columns go at the end
#: A session's cost beside its marks (asked, remarks): `probes`, the targets a demonstration's search tried; `robot_s`,
#: the robot's time so far (every decision, the agent's and the expert's, for the twin's decision period); `resets`,
#: the times the part was put where an episode starts (each agent episode, each demonstration put back to its start);
#: `corrections`, the marks (counted in `asked`) with which a person who stepped in corrected what they had taught.
EVAL_FIELDS = ("step", "success_rate", "mean_return")
#: learner.csv (a run with a learner process), one row per agent episode: the actor's step, the version of the weights
#: it acts with and the actor's step those weights were learned up to (lag_steps: the difference), the learner's
#: updates as last published, and whether the learner's process was alive.
LEARNER_FIELDS = ("step", "weights_version", "weights_step", "lag_steps", "learner_updates", "alive")


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


def truncate_logs(out: Path, step: int) -> None:
    """Drop the rows of metrics.csv, eval.csv and learner.csv in `out` written after `step` (a resumed run writes them
    again)."""
    for name, fields in (("metrics.csv", METRIC_FIELDS), ("eval.csv", EVAL_FIELDS), ("learner.csv", LEARNER_FIELDS)):
        path = out / name
        if not path.exists():
            continue
        with path.open() as fh:
            rows = [r for r in csv.DictReader(fh) if int(r["step"]) <= step]
        replace_csv(path, fields, rows)
