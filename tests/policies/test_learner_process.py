"""The learner in a process of its own (train.learner_process): a split run trains and logs as the in-process run does;
a learner killed mid-run leaves the actor its weights and ends the run with a clear error; a learner that makes no
update never holds up the actor; a split run resumes from its checkpoint. Nothing here depends on how fast the
machine is: where a test needs the learner to have got somewhere, the test (not the actor) waits for it, with a
generous bound."""

from __future__ import annotations

import csv
import dataclasses
import logging
import time

import numpy as np
import pytest
import torch

from mrguide.policies.checkpoint import CheckpointError, read_checkpoint
from mrguide.policies.learner_process import LearnerProcess, LearnerProcessError
from mrguide.policies.learner_server import acting_weights
from mrguide.policies.sac import SACConfig
from mrguide.policies.train import Trainer
from mrguide.policies.train_log import LEARNER_FIELDS, METRIC_FIELDS
from tests.policies import learner_faults
from tests.policies.test_train import flat_state
from tests.run_configs import run_config, sections

pytestmark = pytest.mark.timeout(900)  # a hang fails; the waits below are bounded well within


def make(tmp_path, name, guided=True, split=True, **train) -> Trainer:
    tc, dc, gc, ec = sections()
    short = dict(total_steps=600, learning_starts=64, batch_size=32, eval_every=10_000, checkpoint_every=10_000)
    tc = dataclasses.replace(tc, **{**short, **train}, learner_process=split, publish_every=1)
    dc = dataclasses.replace(dc, hidden=(32, 32))
    gc = dataclasses.replace(gc, intake_steps=400, enabled=guided)
    return Trainer(run_config(tc, dc, gc, ec, sac=SACConfig(hidden=(32, 32), n_critics=4)), tmp_path / name)


def learner(tr: Trainer) -> LearnerProcess:
    assert isinstance(tr.learning, LearnerProcess)
    return tr.learning


def wait_until(tr: Trainer, condition, timeout: float = 300.0) -> None:
    """Take in the learner's publications until `condition()`: the test waits here, not the actor's loop."""
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, f"the learner did not get there within {timeout} s"
        learner(tr).receive()
        time.sleep(0.01)


def read_csv(path) -> tuple[list[str], list[dict]]:
    with path.open() as fh:
        reader = csv.DictReader(fh)
        rows = list(reader)
    return list(reader.fieldnames or ()), rows


def test_a_split_run_trains_and_writes_the_usual_metrics(tmp_path):
    tr = make(tmp_path, "split")
    initial = acting_weights(tr.agent)
    marks: list[int] = []

    def progress(row):
        if not marks and row["step"] >= 200:  # from here on, each metrics row has the learner's statistics
            wait_until(tr, lambda: learner(tr).version >= 1)
            marks.append(row["step"])

    try:
        tr.run(progress)
        assert tr.counters.step == 600 and tr.counters.interventions > 0
        assert learner(tr).version >= 1 and tr.agent.updates >= 1
        moved = acting_weights(tr.agent)
        assert any(not np.array_equal(initial[k], moved[k]) for k in initial)  # the actor acts with learned weights
    finally:
        tr.close()
    header, rows = read_csv(tmp_path / "split" / "metrics.csv")
    assert tuple(header) == METRIC_FIELDS
    assert {r["kind"] for r in rows} == {"agent", "expert"}
    later = [r for r in rows if int(r["step"]) > marks[0]]  # the first takes what was published during the wait
    assert later and later[0]["critic_loss"] and later[0]["q_mean"] and later[0]["expert_ratio"] != "0.0"
    header, learner_rows = read_csv(tmp_path / "split" / "learner.csv")
    assert tuple(header) == LEARNER_FIELDS and all(r["alive"] == "1" for r in learner_rows)
    versions = [int(r["weights_version"]) for r in learner_rows]
    assert versions == sorted(versions) and versions[-1] >= 1
    _, evals = read_csv(tmp_path / "split" / "eval.csv")
    assert [int(e["step"]) for e in evals] == [600]


def test_the_periodic_evaluations_are_made_beside_the_actor_the_final_one_by_it(tmp_path):
    tr = make(tmp_path, "evals", eval_every=200)  # no checkpoint before the end: the results come when they come
    evaluated_here: list[int] = []
    evaluate = tr.evaluate

    def by_the_actor() -> dict:
        evaluated_here.append(tr.counters.step)
        return evaluate()

    tr.evaluate = by_the_actor  # type: ignore[method-assign]
    try:
        tr.run()
    finally:
        tr.close()
    _, rows = read_csv(tmp_path / "evals" / "eval.csv")
    steps = [int(r["step"]) for r in rows]
    # every periodic evaluation arrived, in order (the final one waited for them); only the final one by the actor
    assert len(steps) == tr.counters.evaluations >= 3 and steps == sorted(steps) and steps[-1] == 600
    assert evaluated_here == [600] and all(0.0 <= float(r["success_rate"]) <= 1.0 for r in rows)
    assert tr.last_eval["step"] == 600


def test_the_sac_peer_learns_in_a_learner_process_too(tmp_path):
    tr = make(tmp_path, "sac", learner="sac", total_steps=300)
    initial = acting_weights(tr.agent)
    try:
        tr.run()
        wait_until(tr, lambda: learner(tr).version >= 1)
        moved = acting_weights(tr.agent)
        assert set(moved) == set(initial) and any(k.startswith("actor.log_std.") for k in moved)
        assert any(not np.array_equal(initial[k], moved[k]) for k in initial)
        state = read_checkpoint(tmp_path / "sac" / "checkpoint.pt")
        assert "temperature_opt" in state["agent"] and state["learner"]["seen_step"] == tr.counters.step
    finally:
        tr.close()


def test_a_learner_killed_mid_run_leaves_the_actor_its_weights_and_ends_the_run(tmp_path, caplog):
    tr = make(tmp_path, "killed", guided=False)
    killed: dict = {}

    class KillMidEpisode:
        """Sees every step (as the episode recorder does): kills the learner at step 210, inside an episode."""

        def step(self, trainer, *_):
            if not killed and trainer.counters.step == 210:
                wait_until(tr, lambda: learner(tr).version >= 1)
                killed.update(step=210, version=learner(tr).version)
                learner(tr).process.kill()  # SIGKILL
                learner(tr).process.join(60)

    tr.recorder = KillMidEpisode()
    try:
        with caplog.at_level(logging.ERROR), pytest.raises(LearnerProcessError, match=r"exit code -9") as err:
            tr.run()
        assert "the actor kept the weights of version" in str(err.value)
        assert any("learner process ended" in r.getMessage() for r in caplog.records)
        # the actor went on to the end of the episode it was in, with the weights it had, and stopped there
        assert killed["step"] < tr.counters.step < 600
        assert learner(tr).version >= killed["version"] >= 1
        _, rows = read_csv(tmp_path / "killed" / "metrics.csv")
        assert int(rows[-1]["step"]) == tr.counters.step
        _, learner_rows = read_csv(tmp_path / "killed" / "learner.csv")
        assert learner_rows[-1]["alive"] == "0" and int(learner_rows[-1]["weights_version"]) == learner(tr).version
        assert 0.0 <= tr.evaluate()["success_rate"] <= 1.0  # the kept weights still act
        with pytest.raises(LearnerProcessError, match="no checkpoint written"):
            tr.save_checkpoint()
    finally:
        tr.close()
    assert not (tmp_path / "killed" / "checkpoint.pt").exists()


def test_mrguide_train_ends_with_a_clear_error_when_its_learner_dies(tmp_path, monkeypatch, run_cli):
    monkeypatch.setattr(LearnerProcess, "target", staticmethod(learner_faults.dying))
    monkeypatch.setenv(learner_faults.AFTER, "5")
    out = tmp_path / "cli"
    sets = ("train.learner_process=true", "train.learning_starts=64", "train.batch_size=32", "ddpg.hidden=[32, 32]")
    argv = ["train", "--out", out, "--steps", "300", "--quiet", *(a for s in sets for a in ("--set", s))]
    result = run_cli(argv)
    assert result.code == 1, result.err
    assert "Traceback" not in result.err
    line = result.err.strip().splitlines()[-1]
    assert line.startswith("mrguide train: the learner process ended (exit code 3)")
    assert "no checkpoint was written" in line
    assert not (out / "policy.npz").exists()


def test_a_learner_that_makes_no_updates_never_holds_up_the_actor(tmp_path, monkeypatch, caplog):
    monkeypatch.setattr(LearnerProcess, "target", staticmethod(learner_faults.stalling))
    monkeypatch.setenv(learner_faults.AFTER, "3")
    gate = tmp_path / "gate"
    monkeypatch.setenv(learner_faults.GATE, str(gate))
    tr = make(tmp_path, "slow", guided=False, total_steps=1500)
    seen: dict = {}

    def progress(row):
        if not seen and row["step"] >= 1200:
            learner(tr).receive()
            seen.update(step=row["step"], updates=tr.agent.updates, version=learner(tr).version)
            gate.touch()

    try:
        with caplog.at_level(logging.WARNING):
            tr.run(progress)
        # 1200 actor steps, 1100 of them past learning_starts, while the learner made at most 3 updates
        assert seen["step"] >= 1200 and seen["updates"] <= 3 and seen["version"] <= 3
        assert any("the learner is behind" in r.getMessage() for r in caplog.records)
        _, rows = read_csv(tmp_path / "slow" / "learner.csv")
        assert max(int(r["lag_steps"]) for r in rows) > 1000
        assert tr.counters.step == 1500 and (tmp_path / "slow" / "checkpoint.pt").exists()
    finally:
        tr.close()


def test_a_split_run_resumes_from_its_checkpoint(tmp_path, monkeypatch):
    first = make(tmp_path, "run")
    try:
        first.run(stop_at=250)
    finally:
        first.close()
    saved = read_checkpoint(tmp_path / "run" / "checkpoint.pt")
    with pytest.raises(CheckpointError, match=r"different configuration.*train"):
        make(tmp_path, "run", split=False).load_checkpoint()
    # the resumed learner makes no update until the gate opens: its state must come back exactly as saved
    monkeypatch.setattr(LearnerProcess, "target", staticmethod(learner_faults.stalling))
    monkeypatch.setenv(learner_faults.AFTER, "0")
    gate = tmp_path / "gate"
    monkeypatch.setenv(learner_faults.GATE, str(gate))
    resumed = make(tmp_path, "run")
    try:
        resumed.load_checkpoint()
        state = learner(resumed).state()
        a, b = flat_state(saved["agent"]), flat_state(state["agent"])
        assert a.keys() == b.keys()
        for k in a:
            assert torch.equal(a[k], b[k]) if torch.is_tensor(a[k]) else a[k] == b[k], k
        for pool in ("agent_pool", "expert_pool"):
            assert all(np.array_equal(saved[pool][k], state[pool][k]) for k in saved[pool]), pool
        own, back = saved["learner"], state["learner"]
        assert torch.equal(own.pop("torch_rng"), back.pop("torch_rng")) and own == back
        assert learner(resumed).version == own["version"] and resumed.counters.step == saved["counters"]["step"]
        assert flat_state(resumed.agent.state_dict()).keys() == a.keys()  # the actor acts with the saved weights
        gate.touch()
        resumed.run(stop_at=400)
        assert resumed.counters.step >= 400 and learner(resumed).version >= own["version"]
    finally:
        resumed.close()
    _, rows = read_csv(tmp_path / "run" / "metrics.csv")
    steps = [int(r["step"]) for r in rows]
    assert steps == sorted(steps) and steps[-1] == resumed.counters.step
    _, learner_rows = read_csv(tmp_path / "run" / "learner.csv")
    learner_steps = [int(r["step"]) for r in learner_rows]
    assert learner_steps == sorted(set(learner_steps))  # the rows after the checkpoint were cut back, not doubled


@pytest.mark.parametrize("split", [False, True], ids=["in-process", "learner-process"])
def test_forgetting_empties_both_pools_after_what_was_stored(tmp_path, split):
    """A person's correction (`Learning.forget`): every transition stored before it is gone, in the trainer's process
    and in the learner's alike; what is stored after it is kept."""
    tr = make(tmp_path, "run", split=split)
    try:
        tr.run(stop_at=200)
        rng = np.random.default_rng(0)
        obs, act = rng.uniform(-1, 1, (4, 11)).astype(np.float32), rng.uniform(-1, 1, (4, 4)).astype(np.float32)
        tr.learning.add(obs[0], act[0], 0.0, obs[1], False, 1)  # stored (not yet sent) before the correction
        tr.learning.forget()
        tr.learning.add(obs[1], act[1], 0.0, obs[2], False, 1)  # after it
        tr.learning.add(obs[2], act[2], 0.0, obs[3], False, 0)
        if split:
            learner(tr).stepped(tr.counters.step + 1_000)  # send them
        state = tr.learning.state()
    finally:
        tr.close()
    assert len(state["expert_pool"]["rew"]) == 1 and np.array_equal(state["expert_pool"]["obs"][0], obs[1])
    assert len(state["agent_pool"]["rew"]) == 1 and np.array_equal(state["agent_pool"]["obs"][0], obs[2])
