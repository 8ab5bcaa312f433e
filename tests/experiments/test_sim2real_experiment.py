"""`mrguide experiment sim2real`: train, evaluate each policy under the conditions, report; resumable."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import pytest

from mrguide.cli import main
from mrguide.config import ConfigError
from mrguide.experiments.sim2real_runs import Sim2RealConfig

REAL_CELL = Path(__file__).resolve().parents[2] / "configs" / "cells" / "real_cell.toml"
MUJOCO_CELL = REAL_CELL.with_name("mujoco_cell.toml")


def test_tiny_sim2real_experiment_on_local_ray_evaluates_each_run_once(tiny_experiment, capsys):
    """Conditions 1 and 2 and the MuJoCo cell's, one Ray start: each plays once, the report has a row each."""
    write, out = tiny_experiment
    cfg = write(
        "s2r",
        f'seeds = 1\nsteps = 150\neval_seeds = 1\nepisodes = 1\nconditions = ["sim", "real_exact", "mujoco_exact"]\n'
        f'real_config = "{REAL_CELL}"\nmujoco_config = "{MUJOCO_CELL}"\n',
    )
    assert main(["experiment", "sim2real", "--config", str(cfg), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    outcomes = out / "guided" / "seed0" / "sim2real" / "outcomes.csv"
    with outcomes.open() as fh:
        rows = list(csv.DictReader(fh))
    assert [(r["condition"], r["eval_seed"], r["episode"]) for r in rows] == [
        ("sim", "0", "0"),
        ("real_exact", "0", "0"),
        ("mujoco_exact", "0", "0"),
    ]
    assert all(r["outcome"] for r in rows)
    assert list((outcomes.parent).glob("log-real_exact-seed0.jsonl"))  # the deploy run log of condition 2
    log = outcomes.parent / "log-mujoco_exact-seed0.jsonl"  # and the MuJoCo cell's, played by that engine
    header = json.loads(log.read_text().splitlines()[0])
    assert header["condition"] == "mujoco_exact" and header["plant"]["engine"] == "mujoco"
    summary = (out / "summary.csv").read_text().splitlines()
    assert summary[0].startswith("condition,seeds,episodes,success_rate,ci95_low,ci95_high") and len(summary) == 4
    assert (out / "fig8_sim2real.png").stat().st_size > 10_000
    stamp = outcomes.stat().st_mtime_ns
    capsys.readouterr()
    assert main(["experiment", "sim2real", "--config", str(cfg), "--out", str(out), "--workers", "1", "--quiet"]) == 0
    assert outcomes.stat().st_mtime_ns == stamp  # evaluated once: the second call only reports
    assert main(["experiment", "report", "sim2real", "--config", str(cfg), "--out", str(out)]) == 0
    assert "real_exact" in capsys.readouterr().out


def test_bad_sim2real_experiment_configs_are_refused(tiny_experiment, capsys):
    with pytest.raises(ConfigError, match="conditions"):
        Sim2RealConfig(conditions=("sim", "real"))
    with pytest.raises(ConfigError, match="eval_seeds"):
        Sim2RealConfig(eval_seeds=0)
    write, out = tiny_experiment
    cfg = write("s2r", 'seeds = 1\nsteps = 150\nreal_config = "no_such_cell.toml"\n')
    assert main(["experiment", "sim2real", "--config", str(cfg), "--out", str(out)]) == 2
    assert "no_such_cell.toml" in capsys.readouterr().err and not out.exists()


def test_a_missing_mujoco_cell_is_refused_only_where_a_condition_plays_it(tiny_experiment, capsys):
    write, out = tiny_experiment
    cfg = write(
        "s2r",
        f'seeds = 1\nsteps = 150\nconditions = ["sim", "mujoco_exact"]\nreal_config = "{REAL_CELL}"\n'
        'mujoco_config = "no_such_mujoco_cell.toml"\n',
    )
    assert main(["experiment", "sim2real", "--config", str(cfg), "--out", str(out)]) == 2
    assert "no_such_mujoco_cell.toml" in capsys.readouterr().err and not out.exists()


def test_the_report_gives_each_conditions_parts_per_draw():
    """A draw is one policy under one evaluation seed: its min and median over the draws, per condition."""
    from mrguide.experiments.sim2real_runs import _per_draw

    rows = [
        {"train_seed": t, "condition": "mujoco_hmd", "eval_seed": e, "episode": i, "outcome": outcome}
        for t, e, placed in ((0, 0, 9), (0, 1, 6), (1, 0, 8))
        for i, outcome in enumerate(["success"] * placed + ["no_grasp"] * (10 - placed))
    ]
    table = _per_draw(rows, Sim2RealConfig(conditions=("mujoco_hmd",)))
    assert "| mujoco_hmd | 3 | 6 | 8 |" in table
