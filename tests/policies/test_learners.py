"""The learner registry: the names a config may choose are the learners the trainer can build, and each of them
acts, learns, and survives its own checkpoint round trip through the `Learner` interface alone."""

import numpy as np
import pytest

from mrguide.policies.choices import LEARNERS as LEARNER_NAMES
from mrguide.policies.learners import LEARNERS, make_learner
from mrguide.policies.replay_buffer import TaggedReplay
from mrguide.task import ACT_DIM, OBS_DIM


def test_the_configs_choices_are_the_registered_learners():
    assert set(LEARNER_NAMES) == set(LEARNERS)


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
