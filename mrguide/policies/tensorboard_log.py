"""TensorBoard event files of a training run (`mrguide train --tensorboard`); tensorboard is optional."""

from __future__ import annotations

from pathlib import Path
from typing import ClassVar

from mrguide.policies.train_log import UPDATE_FIELDS


def summary_writer_class() -> type:
    """torch's TensorBoard SummaryWriter; ImportError when the optional `tensorboard` package is missing."""
    from torch.utils.tensorboard import SummaryWriter  # imports tensorboard, which is optional

    return SummaryWriter


class TensorBoardLog:
    """A MetricSink writing TensorBoard event files into `log_dir`, at the training step as global step.

    Tags: train/{critic_loss, actor_loss, q_mean, q_max, bc_loss, expert_ratio} for every metrics row
    with updates in it, train/lambda and annotations/{asked, reused, remarks, skipped} per metrics row
    (once per step), eval/{success_rate, mean_return} per evaluation. On a resume pass the step of the
    checkpoint + 1 as `purge_step`: TensorBoard then hides what an earlier process wrote after the
    checkpoint (those episodes run again), as metrics.csv drops those rows. Close it when done.
    """

    ROW_TAGS: ClassVar[dict[str, str]] = {k: f"train/{k}" for k in (*UPDATE_FIELDS, "expert_ratio")}
    PER_STEP_TAGS: ClassVar[dict[str, str]] = {
        "lambda": "train/lambda",
        **{k: f"annotations/{k}" for k in ("asked", "reused", "remarks", "skipped")},
    }
    EVAL_TAGS: ClassVar[dict[str, str]] = {"success_rate": "eval/success_rate", "mean_return": "eval/mean_return"}

    def __init__(self, log_dir: str | Path, purge_step: int | None = None):
        self.writer = summary_writer_class()(log_dir=str(log_dir), purge_step=purge_step)
        self._last_step: int | None = None

    def row(self, row: dict) -> None:
        step = row["step"]
        if row["critic_loss"] != "":  # expert_ratio of a row without updates only repeats the previous one
            for key, tag in self.ROW_TAGS.items():
                if row[key] != "":
                    self.writer.add_scalar(tag, row[key], step)
        if step != self._last_step:  # an agent row after its expert row shares the step and the counters
            for key, tag in self.PER_STEP_TAGS.items():
                self.writer.add_scalar(tag, row[key], step)
            self._last_step = step

    def evaluation(self, res: dict) -> None:
        for key, tag in self.EVAL_TAGS.items():
            self.writer.add_scalar(tag, res[key], res["step"])

    def close(self) -> None:
        self.writer.close()
