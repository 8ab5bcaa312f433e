"""Synthetic finished runs for the report tests, and a tiny training config for the Ray tests."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from mrguide.policies.train_log import METRIC_FIELDS

TINY_TRAINING = """
[train]
learning_starts = 64
batch_size = 32
eval_every = 150
eval_episodes = 2
checkpoint_every = 60
[ddpg]
hidden = [16, 16]
[guidance]
intake_steps = 300
"""


def write_run(run: Path, eval_rates, asked_per_row, wall: float = 100.0, rows=None) -> None:
    """A finished run: eval.csv (one evaluation per 1000 steps), metrics.csv (a row per 500 steps, the wall time
    growing evenly to `wall`, each row updated with `rows[i]` if given), done."""
    run.mkdir(parents=True)
    with (run / "eval.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, ["step", "success_rate", "mean_return"])
        w.writeheader()
        w.writerows(
            {"step": 1000 * (i + 1), "success_rate": r, "mean_return": 10 * r} for i, r in enumerate(eval_rates)
        )
    with (run / "metrics.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, METRIC_FIELDS, restval="0")
        w.writeheader()
        for i, asked in enumerate(asked_per_row):
            w.writerow(
                {
                    "step": 500 * (i + 1),
                    "asked": asked,
                    "expert_ratio": 0.5,
                    "wall_s": wall * (i + 1) / len(asked_per_row),
                    **(rows[i] if rows else {}),
                }
            )
    (run / "done").write_text(json.dumps({"wall_s": wall, "update_ms": 5.0, "steps": 1000 * len(eval_rates)}))


@pytest.fixture
def tiny_experiment(tmp_path):
    """(experiment TOML writer, experiment dir): a training config small enough for seconds per run."""
    (tmp_path / "train.toml").write_text(TINY_TRAINING)

    def write(name: str, body: str) -> Path:
        path = tmp_path / f"{name}.toml"
        path.write_text('[experiment]\nconfig = "train.toml"\n' + body)
        return path

    return write, tmp_path / "out"
