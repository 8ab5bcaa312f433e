"""On-cell learning's learner side: the training run's learner goes on from its checkpoint in a process of its own,
takes the cell's transitions between episodes, publishes versions as policy files the runtime takes in; a learner
that dies leaves the cell acting on with the last version; `--resume` goes on from the saved state."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from mrguide.deploy.cell_learning import LearningConfig
from mrguide.deploy.policy import ExportedPolicy
from mrguide.errors import InputError
from mrguide.policies.cell_learner import ON_CELL, STATE, CellLearner
from mrguide.policies.export import export_actor
from mrguide.policies.train import Trainer
from mrguide.robot import load_robot
from mrguide.task import OBS_DIM, Outcome
from tests.run_configs import run_config, sections


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A short training run with its checkpoint and exported policy."""
    tc, dc, gc, ec = sections()
    tc = dataclasses.replace(
        tc, total_steps=400, learning_starts=64, batch_size=32, eval_every=10**4, checkpoint_every=10**4
    )
    out = tmp_path_factory.mktemp("run")
    tr = Trainer(run_config(tc, dataclasses.replace(dc, hidden=(32, 32)), gc, ec), out)
    try:
        tr.run(stop_at=200)
        tr.save_checkpoint()
        export_actor(tr.agent.policy_actor, out / "policy.npz", tr.env.robot_spec, tr.env.task_cfg, 0.1)
        return out, tr.env.task_cfg
    finally:
        tr.close()


def _learner(run_dir, task, resume=False, trial: int = 0) -> CellLearner:
    """The learner of `run_dir`; each newer version taken in at once unless `trial`."""
    spec, learning = load_robot(), LearningConfig(trial=trial)
    policy = ExportedPolicy.load(run_dir / "policy.npz", spec, task)
    return CellLearner(run_dir, policy, spec, task, learning, 0, resume)


def _episode(learner: CellLearner, rng: np.random.Generator, decisions: int = 20) -> None:
    """A cell episode of `decisions` judged decisions, then the next episode's start."""
    tap = learner.actor.tap
    obs = np.array([0.5, 0.0, 0.3, -1.0, 0.0, 0.5, -0.1, 0.025, 0.4, 0.2, 0.025])
    for i in range(decisions):
        tap.acted(obs, rng.uniform(-1.0, 1.0, 4))
        obs = obs + rng.normal(0.0, 0.01, OBS_DIM)
        tap.judged(obs, -1.0, Outcome.NO_GRASP if i == decisions - 1 else None)
    learner.actor.episode_start(0, lambda kind, **fields: None, _no_sensing)


def _no_sensing():
    raise AssertionError("nobody intervenes: the cell is not sensed for marks")


def _until_a_version(learner: CellLearner, rng, deadline_s: float = 300.0) -> None:
    end = time.monotonic() + deadline_s
    while learner.version == 0 and time.monotonic() < end:
        _episode(learner, rng)
        time.sleep(0.05)


def test_the_learner_goes_on_from_the_training_run_and_publishes_versions_the_cell_takes_in(trained):
    run_dir, task = trained
    learner = _learner(run_dir, task)
    try:
        rng = np.random.default_rng(0)
        _until_a_version(learner, rng)
        version = learner.version
        assert version > 0 and (run_dir / ON_CELL / f"policy-v{version}.npz").exists()
        assert learner.counters.step > 200  # the schedule goes on from the training run's last step
        assert learner.status()["lost"] is None and learner.status()["updates"] > 0
        with pytest.raises(InputError, match="--resume"):
            _learner(run_dir, task)  # a second session into the same folder: refused, nothing lost
    finally:
        learner.close()
    assert (run_dir / ON_CELL / STATE).exists()
    again = _learner(run_dir, task, resume=True)
    try:
        assert again.version >= version  # it acts with the version it had, loaded from its own file
        assert again.counters.step == learner.counters.step
    finally:
        again.close()


def test_a_learner_that_dies_leaves_the_cell_acting_with_its_last_version(trained, tmp_path):
    run_dir = tmp_path / "copy"
    run_dir.mkdir()
    for name in ("checkpoint.pt", "policy.npz"):
        (run_dir / name).write_bytes((trained[0] / name).read_bytes())
    learner = _learner(run_dir, trained[1])
    try:
        learner.learner.process.kill()
        learner.learner.process.join(10)
        rng = np.random.default_rng(1)
        for _ in range(3):
            _episode(learner, rng)  # no exception: the cell goes on
        assert learner.lost is not None and "ended" in learner.lost
        assert learner.version == 0 and learner.status()["lost"]
    finally:
        learner.close()


def test_a_resumed_session_acts_with_the_version_its_trials_kept(trained, tmp_path):
    run_dir = tmp_path / "copy"
    run_dir.mkdir()
    for name in ("checkpoint.pt", "policy.npz"):
        (run_dir / name).write_bytes((trained[0] / name).read_bytes())
    learner = _learner(run_dir, trained[1], trial=2)
    try:
        _until_a_version(learner, np.random.default_rng(2))
        tried = learner.version
        assert learner.actor.versions.gate.trying and learner.actor.versions.kept_version == 0
        for _ in range(2):
            learner.actor.episode_end(0, Outcome.SUCCESS, lambda kind, **fields: None)
        assert learner.status()["kept_version"] == tried and learner.status()["versions_kept"] == 1
    finally:
        learner.close()
    again = _learner(run_dir, trained[1], resume=True, trial=2)
    try:
        assert again.version == again.actor.versions.kept_version == tried  # from its own policy file
        assert again.actor.versions.gate.state() == learner.actor.versions.gate.state()
    finally:
        again.close()
