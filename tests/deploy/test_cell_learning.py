"""On-cell learning's actor side: the runtime's decisions become transitions of what the cell sensed, and a newer
policy file is taken in between episodes only after the checks a file for the robot gets."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.deploy.cell_learning import LearningActor, LearningConfig, PolicyVersions, Transition, TransitionTap
from mrguide.deploy.interventions import CellStart
from mrguide.deploy.policy import ExportedPolicy
from mrguide.deploy.runlog import RunLog, read_log
from mrguide.deploy.runtime import Runtime
from mrguide.deploy.runtime_config import RuntimeConfig
from mrguide.deploy.session import FixedObjectPose
from mrguide.robot import load_robot
from mrguide.task import OBS_DIM, Outcome, TaskConfig
from tests.deploy.test_runtime_interface import IdealCobot


def _policy_file(path, seed: int, task: TaskConfig, period: float = 0.1):
    from mrguide.policies.ddpg import DDPG, DDPGConfig
    from mrguide.policies.export import export_actor
    from mrguide.policies.networks import obs_scaling

    spec = load_robot()
    agent = DDPG(*obs_scaling(spec.workspace), 4, DDPGConfig(), seed=seed)
    return export_actor(agent.actor, path, spec, task, period)


def test_the_tap_pairs_each_action_with_the_next_judgement():
    got: list[Transition] = []
    tap = TransitionTap(got.append)
    s = [np.full(OBS_DIM, float(i)) for i in range(4)]
    tap.judged(s[0], None, None)  # the first decision judges nothing
    tap.acted(s[0], np.array([0.2, 2.0, -3.0, 1.0]))
    tap.judged(s[1], -1.5, None)
    tap.acted(s[1], np.array([np.nan, 0.0, 0.0, 1.0]))  # refused by the decision step: nothing carried out
    tap.judged(s[2], -1.0, None)
    tap.acted(s[2], np.zeros(4))
    tap.judged(s[3], 10.0, Outcome.SUCCESS)
    tap.acted(s[3], np.zeros(4))
    tap.reset()  # a new episode: the unjudged action is dropped
    tap.judged(s[0], -1.0, None)
    assert [(t.obs[0], t.next_obs[0], t.reward, t.done) for t in got] == [
        (0.0, 1.0, -1.5, False),
        (2.0, 3.0, 10.0, True),
    ]
    assert np.array_equal(got[0].action, np.array([0.2, 1.0, -1.0, 1.0], np.float32))  # clipped to the action box
    tap.expert = True
    tap.acted(s[0], np.zeros(4))
    tap.judged(s[1], -1.0, Outcome.NO_GRASP)  # the horizon: truncated, not ended
    assert got[-1].expert and not got[-1].done


def test_a_newer_policy_is_taken_in_only_when_it_passes_the_checks(tmp_path):
    spec, task = load_robot(), TaskConfig(horizon=8)
    first = ExportedPolicy.load(_policy_file(tmp_path / "v0.npz", 0, task), spec, task)
    changes = []
    versions = PolicyVersions(first, spec, task, LearningConfig(trial=0), on_change=lambda *a: changes.append(a))
    obs = np.array([0.5, 0.0, 0.3, -1.0, 0.0, 0.5, -0.1, 0.025, 0.4, 0.2, 0.025])
    versions.offer(2, _policy_file(tmp_path / "v2.npz", 2, task))
    versions.offer(1, _policy_file(tmp_path / "v1.npz", 1, task))  # older than what was offered: ignored
    assert versions(obs).tolist() == first(obs).tolist()  # not before the next episode
    assert versions.take_newest() == 2 and changes[-1][2] is None
    assert versions(obs).tolist() != first(obs).tolist()
    broken = tmp_path / "v3.npz"
    broken.write_bytes(b"not a policy")
    versions.offer(3, broken)
    assert versions.take_newest() == 2 and "v3.npz" in changes[-1][2]  # refused, said, the old one acts on
    versions.offer(4, _policy_file(tmp_path / "v4.npz", 4, task, period=0.2))
    assert versions.take_newest() == 2 and "decision period" in changes[-1][2]


def test_a_newer_version_is_kept_only_after_its_trial_and_a_failure_brings_back_the_kept_one(tmp_path):
    spec, task = load_robot(), TaskConfig(horizon=8)
    files = {v: _policy_file(tmp_path / f"v{v}.npz", v, task) for v in range(5)}
    obs = np.array([0.5, 0.0, 0.3, -1.0, 0.0, 0.5, -0.1, 0.025, 0.4, 0.2, 0.025])
    first = ExportedPolicy.load(files[0], spec, task)
    versions = PolicyVersions(first, spec, task, LearningConfig(trial=3))
    versions.offer(1, files[1])
    assert versions.take_newest() == 1 and versions.gate.trying and versions.kept_version == 0
    versions.offer(2, files[2])
    for outcome in (Outcome.SUCCESS, Outcome.POSE_LOST, Outcome.SUCCESS):  # the supervisor's end judges nothing
        assert versions.episode_end(outcome) is None and versions.take_newest() == 1  # no newer one mid-trial
    assert versions.episode_end(Outcome.SUCCESS) == "kept" and versions.kept_version == 1
    assert versions.take_newest() == 2  # the next try at once after a version kept
    assert versions.episode_end(Outcome.DROPPED) == "dropped" and versions.version == 1
    assert versions(obs).tolist() == ExportedPolicy.load(files[1], spec, task)(obs).tolist()  # the kept one acts
    versions.offer(2, files[2])
    assert [versions.take_newest() for _ in range(4)] == [1, 1, 1, 1]  # `trial` episodes; v2 is never tried again
    versions.offer(3, files[3])
    assert versions.take_newest() == 3
    versions.offer(4, files[4])
    assert versions.episode_end(Outcome.NO_GRASP) == "dropped"
    assert [versions.take_newest() for _ in range(7)] == [1] * 6 + [4]  # twice as long after two dropped in a row
    assert versions.gate.state() == {"wait": 0, "backoff": 12, "kept": 1, "dropped": 2}


def test_the_runtime_as_actor_hands_over_every_decision_it_carried_out(tmp_path):
    spec, task = load_robot(), TaskConfig(horizon=8)
    policy = ExportedPolicy.load(_policy_file(tmp_path / "p.npz", 0, task), spec, task)
    got: list[Transition] = []
    cobot = IdealCobot(spec.q_home)
    with (
        RunLog(tmp_path / "log.jsonl", {"test": "learning"}) as log,
        Runtime(cobot, policy, FixedObjectPose((0.5, -0.075, 0.025)), spec, task, log, 0.1, RuntimeConfig()) as rt,
    ):
        versions = PolicyVersions(policy, spec, task)
        rt.policy, rt.learning = versions, LearningActor(versions, TransitionTap(got.append))
        versions.offer(1, _policy_file(tmp_path / "p1.npz", 1, task))
        report = rt.run_episode(np.array([0.5, 0.21, 0.025]), 0)
    assert report.outcome is Outcome.NO_GRASP  # the cup never seals on this cobot
    records = read_log(tmp_path / "log.jsonl")
    assert [r["version"] for r in records if r["kind"] == "policy_version"] == [1]
    trials = [r for r in records if r["kind"] == "policy_trial"]
    assert [(t["version"], t["verdict"], t["acting"]) for t in trials] == [(1, "dropped", 0)]  # no seal: v0 again
    decisions = [r for r in records if r["kind"] == "decision"]
    acted = [r for r in decisions if "action" in r]
    assert len(got) == len(acted) == task.horizon
    for i, t in enumerate(got):
        assert np.allclose(t.obs, acted[i]["obs"], atol=1e-6)
        assert t.reward == pytest.approx(decisions[i + 1]["reward"])
    assert np.allclose(got[0].next_obs, acted[1]["obs"], atol=1e-6)
    assert not any(t.done for t in got)  # the horizon truncates: the learner bootstraps past it


def test_exploration_adds_seeded_noise_inside_the_action_box(tmp_path):
    spec, task = load_robot(), TaskConfig(horizon=8)
    policy = ExportedPolicy.load(_policy_file(tmp_path / "p.npz", 0, task), spec, task)
    obs = np.array([0.5, 0.0, 0.3, -1.0, 0.0, 0.5, -0.1, 0.025, 0.4, 0.2, 0.025])
    a, b = (PolicyVersions(policy, spec, task, LearningConfig(exploration=0.1), seed=3) for _ in range(2))
    noisy = np.array([a(obs) for _ in range(50)])
    assert np.array_equal(noisy, np.array([b(obs) for _ in range(50)]))  # seeded
    assert np.all(np.abs(noisy) <= 1.0) and np.std(noisy[:, 0]) > 0.05
    assert np.array_equal(PolicyVersions(policy, spec, task)(obs), policy(obs))  # none by default


class _Person:
    """Interventions that a test scripts: who steps in, and the expert (or the reason for none) their marks give."""

    def __init__(self, expert, reason: str | None = None):
        self.expert, self.reason = expert, reason
        self.asked: list[CellStart] = []
        self.who: str | None = "c1"
        self.status: list[dict] = []

    def requested(self):
        who, self.who = self.who, None
        return who

    def demonstration(self, episode, start):
        self.asked.append(start)
        return self.expert, {"marks": [], "reason": self.reason}

    def publish(self, **status):
        self.status.append(status)


class _Hover:
    """A demonstration that holds the TCP over the part (the vacuum off)."""

    def __init__(self, spec):
        self.action = np.r_[spec.workspace.to_normalized(np.array([0.5, -0.075, 0.12])), -1.0].astype(np.float32)

    def act(self, obs):
        return self.action


def _learning_episode(tmp_path, person, name: str):
    """One learning episode on the ideal cobot with `person` stepping in: (transitions, run log records, actor)."""
    spec, task = load_robot(), TaskConfig(horizon=8)
    policy = ExportedPolicy.load(_policy_file(tmp_path / "p.npz", 0, task), spec, task)
    got: list[Transition] = []
    with (
        RunLog(tmp_path / name, {"test": "interventions"}) as log,
        Runtime(IdealCobot(spec.q_home), policy, FixedObjectPose((0.5, -0.075, 0.025)), spec, task, log, 0.1) as rt,
    ):
        actor = LearningActor(PolicyVersions(policy, spec, task), TransitionTap(got.append), interventions=person)
        rt.policy, rt.learning = actor, actor
        rt.run_episode(np.array([0.5, 0.21, 0.025]), 0)
        actor.cycle_done(0, False)
    return got, read_log(tmp_path / name), actor


def test_an_intervention_is_taken_at_the_episode_start_and_its_decisions_are_expert_data(tmp_path):
    spec = load_robot()
    hover = _Hover(spec)
    person = _Person(hover)
    got, records, actor = _learning_episode(tmp_path, person, "expert.jsonl")
    (start,) = person.asked  # asked once, before the first decision, with the cell as the runtime senses it
    first = next(r for r in records if r["kind"] == "decision")
    assert np.allclose(start.obs, first["obs"], atol=1e-6) and np.allclose(start.joints, spec.q_home)
    acted = [r for r in records if r["kind"] == "decision" and "action" in r]
    assert all(np.allclose(r["action"], hover.action) for r in acted)  # the expert played every decision
    assert len(got) == len(acted) and all(t.expert for t in got)
    (record,) = [r for r in records if r["kind"] == "intervention"]
    assert record["episode"] == 0 and record["client_id"] == "c1" and record["played_by"] == "expert"
    assert actor.counts.as_dict() == {"interventions": 1, "interventions_asked": 1, "interventions_fell_back": 0}
    assert person.status[-1]["interventions"] == 1 and person.status[-1]["cycle"] == 0


def test_an_intervention_nobody_marks_leaves_the_episode_to_the_policy(tmp_path):
    got, records, actor = _learning_episode(tmp_path, _Person(None, reason="timeout"), "policy.jsonl")
    assert got and not any(t.expert for t in got)
    (record,) = [r for r in records if r["kind"] == "intervention"]
    assert record["played_by"] == "policy" and record["reason"] == "timeout"
    assert actor.counts.as_dict() == {"interventions": 0, "interventions_asked": 1, "interventions_fell_back": 1}
