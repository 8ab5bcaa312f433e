"""The learner registry: each registered learner acts, learns, and survives its own checkpoint round trip through the
`Learner` interface alone; a learner added by one module, with a section of its own, trains by its name through
`mrguide train`, shows in `mrguide config show` and resumes, with its name listed nowhere else."""

import dataclasses

import numpy as np
import pytest

from mrguide.policies.ddpg import DDPG, DDPGConfig
from mrguide.policies.learners import LEARNERS, LearnerEntry, make_learner, register_learner
from mrguide.policies.replay_buffer import TaggedReplay
from mrguide.policies.train import Trainer
from mrguide.task import ACT_DIM, OBS_DIM
from tests.run_configs import run_config, sections


@pytest.mark.parametrize("name", sorted(LEARNERS))
def test_a_registered_learner_acts_learns_and_restores(name):
    entry = LEARNERS[name]
    settings = entry.config()
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


def test_a_registered_learner_trains_by_its_name_and_a_name_is_registered_once(toy_learner, tmp_path):
    tc, dc, gc, ec = sections()
    tc = dataclasses.replace(tc, learner=toy_learner, total_steps=200, learning_starts=64, batch_size=32)
    tr = Trainer(
        run_config(dataclasses.replace(tc, eval_every=10_000), dataclasses.replace(dc, hidden=(16, 16)), gc, ec),
        tmp_path,
    )
    try:
        tr.run(stop_at=150)
    finally:
        tr.close()
    assert isinstance(tr.agent, CountingDDPG) and CountingDDPG.learned == tr.agent.updates > 0
    with pytest.raises(ValueError, match="registered already"):
        register_learner("sac", LearnerEntry(CountingDDPG, "ddpg", DDPGConfig))


@dataclasses.dataclass(frozen=True)
class ToyConfig(DDPGConfig):
    """[toy]: guided DDPG's settings and one of its own."""

    note: int = 0


@pytest.fixture
def toy_with_section():
    register_learner("toy", LearnerEntry(CountingDDPG, "toy", ToyConfig))
    yield "toy"
    del LEARNERS["toy"]


def test_a_learner_with_a_section_of_its_own_trains_shows_and_resumes(toy_with_section, tmp_path, capsys):
    import json

    from mrguide.cli import main

    cfg = tmp_path / "toy.toml"
    cfg.write_text(  # no update (learning starts after the run): what is tested is where the learner is named
        "[train]\nlearner = 'toy'\nlearning_starts = 100000\neval_episodes = 1\n\n[toy]\nhidden = [16, 16]\n"
    )
    out = str(tmp_path / "run")
    argv = ["train", "--config", str(cfg), "--out", out, "--quiet", "--steps", "300"]
    assert main([*argv, "--stop-after", "100"]) == 0
    capsys.readouterr()
    assert main(["config", "show", "--config", str(cfg)]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert shown["toy"]["hidden"] == [16, 16] and shown["toy"]["note"] == 0
    assert main([*argv, "--resume", "--stop-after", "200", "--set", "sac.utd=3"]) == 0  # not the trained learner's
    assert main([*argv, "--resume", "--set", "toy.note=1"]) == 2
    assert "sections differ: toy" in capsys.readouterr().err
