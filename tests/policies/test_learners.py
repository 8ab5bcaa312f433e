"""The learner registry: the names a config may choose are the learners the trainer can build, and each of them
acts, learns, and survives its own checkpoint round trip through the `Learner` interface alone."""

import dataclasses

import numpy as np
import pytest

from mrguide.policies.choices import LEARNER_NAMES
from mrguide.policies.ddpg import DDPG, DDPGConfig
from mrguide.policies.learners import LEARNERS, LearnerEntry, make_learner, register_learner
from mrguide.policies.replay_buffer import TaggedReplay
from mrguide.policies.train import Trainer
from mrguide.policies.train_config import load_train_config
from mrguide.task import ACT_DIM, OBS_DIM


def test_the_configs_choices_are_the_registered_learners():
    assert list(LEARNERS) == LEARNER_NAMES


@pytest.mark.parametrize("name", sorted(LEARNERS))
def test_a_registered_learner_acts_learns_and_restores(name):
    entry = LEARNERS[name]
    settings = {entry.section: entry.config()}
    offset, scale = np.zeros(OBS_DIM), np.ones(OBS_DIM)
    agent = make_learner(name, settings, offset, scale, ACT_DIM, seed=3)
    rng = np.random.default_rng(0)
    replay = TaggedReplay(64, OBS_DIM, ACT_DIM)
    for i in range(64):
        obs = rng.uniform(-1, 1, OBS_DIM)
        replay.add(obs, rng.uniform(-1, 1, ACT_DIM), -1.0, obs, False, i % 2)
    stats, share = agent.learn(replay, 0.5, 32, rng)
    assert agent.updates >= 1 and 0.0 <= share <= 1.0
    assert stats and all(np.isfinite(v) for v in stats.values())
    obs = rng.uniform(-1, 1, OBS_DIM)
    action = agent.act(obs)
    assert action.shape == (ACT_DIM,) and np.all(np.abs(action) <= 1.0)
    again = make_learner(name, settings, offset, scale, ACT_DIM, seed=4)
    assert not np.array_equal(again.act(obs), action)  # another seed, other weights: the restore below matters
    again.load_state_dict(agent.state_dict())
    np.testing.assert_array_equal(again.act(obs), action)


class CountingDDPG(DDPG):
    """Guided DDPG, counting the environment steps it learned from."""

    learned = 0

    def learn(self, replay, lam, batch_size, rng):
        CountingDDPG.learned += 1
        return super().learn(replay, lam, batch_size, rng)


@pytest.fixture
def toy_learner():
    register_learner("toy-ddpg", LearnerEntry(CountingDDPG, "ddpg", DDPGConfig))
    CountingDDPG.learned = 0
    yield "toy-ddpg"
    del LEARNERS["toy-ddpg"]
    LEARNER_NAMES.remove("toy-ddpg")


def test_a_registered_learner_trains_by_its_name_and_a_name_is_registered_once(toy_learner, tmp_path):
    tc, dc, gc, ec = load_train_config(None)
    tc = dataclasses.replace(tc, learner=toy_learner, total_steps=200, learning_starts=64, batch_size=32)
    tr = Trainer(dataclasses.replace(tc, eval_every=10_000), dataclasses.replace(dc, hidden=(16, 16)), gc, ec, tmp_path)
    try:
        tr.run(stop_at=150)
    finally:
        tr.close()
    assert isinstance(tr.agent, CountingDDPG) and CountingDDPG.learned == tr.agent.updates > 0
    with pytest.raises(ValueError, match="registered already"):
        register_learner("sac", LearnerEntry(CountingDDPG, "ddpg", DDPGConfig))
