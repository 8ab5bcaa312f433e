"""`mrguide deploy --dry-run --cycles N --learn RUN_DIR`: the runtime acts, the training run's learner learns beside it
from the cell's transitions, the versions it publishes are taken in between episodes; a second session into the
same folder is refused unless it resumes."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from mrguide.cli import main
from mrguide.deploy.runlog import read_log
from mrguide.policies.cell_learner import ON_CELL, STATE
from mrguide.policies.export import export_actor
from mrguide.policies.train import Trainer
from tests.run_configs import run_config, sections

REAL = Path(__file__).parents[2] / "configs" / "cells" / "real_cell.toml"


@pytest.fixture()
def run_dir(tmp_path) -> Path:
    """A short training run: its checkpoint and policy."""
    tc, dc, gc, ec = sections()
    tc = dataclasses.replace(tc, total_steps=400, learning_starts=64, batch_size=32, eval_every=10**4)
    tr = Trainer(run_config(tc, dataclasses.replace(dc, hidden=(32, 32)), gc, ec), tmp_path / "run")
    try:
        tr.run(stop_at=200)
        tr.save_checkpoint()
        export_actor(tr.agent.policy_actor, tr.out / "policy.npz", tr.env.robot_spec, tr.env.task_cfg, 0.1)
    finally:
        tr.close()
    return tr.out


def test_a_dry_run_learns_on_the_cell_and_a_second_session_must_resume(run_dir, tmp_path, capsys):
    log = tmp_path / "cycles.jsonl"
    args = ["deploy", "--dry-run", "--config", str(REAL), "--policy", str(run_dir / "policy.npz"), "--quiet"]
    args += ["--set", "deploy.cycles.max_retries=0", "--set", "deploy.cycles.on_alarm=skip", "--log", str(log)]
    assert main([*args, "--cycles", "2", "--learn", str(run_dir)]) == 0
    records = read_log(log)
    assert len([r for r in records if r["kind"] == "policy_version"]) == 2  # one per episode
    assert [r["cycle"] for r in records if r["kind"] == "scored"] == [0, 1]  # the dry run's truth, per cycle
    (learning,) = [r for r in records if r["kind"] == "learning"]
    assert learning["lost"] is None
    assert (run_dir / ON_CELL / STATE).exists() and (run_dir / ON_CELL / "learner.csv").exists()
    assert main([*args, "--cycles", "3", "--learn", str(run_dir)]) == 2  # not over the first session's files
    assert "--resume" in capsys.readouterr().err
