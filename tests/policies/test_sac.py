"""The peer learner (SAC as RLPD uses it): sampling, log-probabilities, updates, checkpoints, a training run."""

import dataclasses
import io

import numpy as np
import pytest
import torch

from mrguide.config import ConfigError
from mrguide.policies.networks import obs_scaling
from mrguide.policies.replay_buffer import TaggedReplay
from mrguide.policies.sac import SAC, SACConfig
from mrguide.robot import load_robot

SMALL = SACConfig(hidden=(32, 32), n_critics=4)


def _agent(cfg=SMALL, seed=0):
    return SAC(*obs_scaling(load_robot().workspace), 4, cfg, seed=seed)


def _replay(n=600, expert_every=3, seed=0):
    rng = np.random.default_rng(seed)
    replay = TaggedReplay(10_000, 11, 4)
    for i in range(n):
        obs = np.concatenate(
            [rng.uniform([0.3, -0.2, 0.05], [0.65, 0.4, 0.3]), [1.0, 0.2], [0.5, 0.0, 0.025], [0.5, 0.2, 0.025]]
        )
        replay.add(obs, rng.uniform(-1, 1, 4), float(rng.normal()), obs, False, int(i % expert_every == 0))
    return replay


def test_log_probability_is_the_tanh_gaussians():
    """log π of the sampled y equals torch's own TanhTransform of the Normal; the action is the head's for y."""
    agent = _agent()
    obs = torch.as_tensor(_replay(8).agent.obs[:5])
    eps = torch.randn(5, 4)
    action, logp = agent.actor.sample(obs, eps)
    h = agent.actor.base.net[:-2](agent.actor.base.inputs(obs))
    mean, log_std = agent.actor.base.net[-2](h), agent.actor.log_std(h).clamp(-20, 2)
    dist = torch.distributions.TransformedDistribution(
        torch.distributions.Normal(mean, log_std.exp()), [torch.distributions.TanhTransform()]
    )
    y = torch.tanh(mean + log_std.exp() * eps)
    assert torch.allclose(action, agent.actor.base.output(obs, y))
    assert torch.allclose(logp, dist.log_prob(y.clamp(-1 + 1e-6, 1 - 1e-6)).sum(-1), atol=1e-3)


def test_deterministic_action_is_the_exported_actor_and_exploration_samples():
    agent = _agent()
    obs = _replay(2).agent.obs[0]
    det = agent.act(obs)
    assert np.allclose(det, agent.policy_actor(torch.as_tensor(obs).unsqueeze(0)).detach().numpy()[0], atol=1e-6)
    rng = np.random.default_rng(0)
    samples = np.array([agent.act(obs, rng) for _ in range(50)])
    assert samples.std(0).min() > 0.05 and np.all(np.abs(samples) <= 1.0)  # an untrained policy: broad


def test_every_batch_is_half_expert_and_learning_steps_utd_critics():
    agent = _agent(dataclasses.replace(SMALL, utd=3))
    replay = _replay()
    rng = np.random.default_rng(1)
    stats, ratio = agent.learn(replay, lam=0.9, batch_size=64, rng=rng)  # λ does not matter
    assert ratio == 0.5 and agent.updates == 3
    assert set(stats) == set(SAC.CRITIC_STATS + SAC.ACTOR_STATS) and all(np.isfinite(v) for v in stats.values())
    only_agent = TaggedReplay(100, 11, 4)
    only_agent.add(replay.agent.obs[0], replay.agent.act[0], 0.0, replay.agent.obs[0], False, 0)
    assert agent.learn(only_agent, 0.5, 8, rng)[1] == 0.0  # no demonstrations yet: agent data only


def test_learning_fits_the_critic_and_tunes_the_temperature():
    agent = _agent()
    replay = _replay()
    rng = np.random.default_rng(2)
    first = agent.learn(replay, 0.5, 128, rng)[0]
    for _ in range(150):
        last = agent.learn(replay, 0.5, 128, rng)[0]
    assert last["critic_loss"] < first["critic_loss"]
    assert last["temperature"] < first["temperature"]  # the entropy starts above its target (sac.target_entropy)


def test_state_round_trip_continues_identically():
    a, b = _agent(seed=3), _agent(seed=4)
    replay = _replay()
    for _ in range(5):
        a.learn(replay, 0.5, 32, np.random.default_rng(0))
    buffer = io.BytesIO()  # through bytes, as a checkpoint file: the optimizers' state tensors are not shared
    torch.save(a.state_dict(), buffer)
    buffer.seek(0)
    b.load_state_dict(torch.load(buffer))
    obs = replay.agent.obs[3]
    assert np.array_equal(a.act(obs), b.act(obs)) and b.updates == a.updates
    torch.manual_seed(9)
    sa = a.learn(replay, 0.5, 32, np.random.default_rng(5))[0]
    torch.manual_seed(9)
    sb = b.learn(replay, 0.5, 32, np.random.default_rng(5))[0]
    assert sa == sb


@pytest.mark.parametrize(
    "field, value",
    [("n_min", 11), ("utd", 0), ("expert_fraction", 1.5), ("hidden", ()), ("target_entropy", float("nan"))],
)
def test_sac_config_refuses_bad_values(field, value):
    with pytest.raises(ConfigError, match=f"sac.{field}"):
        SACConfig(**{field: value})


def test_a_short_guided_sac_run_trains_resumes_and_exports(tmp_path):
    from mrguide.deploy.policy import ExportedPolicy
    from mrguide.policies.export import export_actor
    from mrguide.policies.train import Trainer
    from tests.run_configs import run_config, sections

    tc, dc, gc, ec = sections()
    tc = dataclasses.replace(
        tc, total_steps=400, learning_starts=64, batch_size=32, eval_every=10_000, checkpoint_every=200, learner="sac"
    )
    sc = SMALL
    tr = Trainer(run_config(tc, dc, gc, ec, sac=sc), tmp_path)
    try:
        tr.run(stop_at=200)
        tr.save_checkpoint()
    finally:
        tr.close()
    again = Trainer(run_config(tc, dc, gc, ec, sac=sc), tmp_path)
    try:
        again.load_checkpoint()
        assert again.counters.step == tr.counters.step and again.agent.updates == tr.agent.updates
        again.run()
        path = export_actor(
            again.agent.policy_actor,
            tmp_path / "policy.npz",
            again.env.robot_spec,
            again.env.task_cfg,
            again.env.twin_cfg.decision_period,
        )
        obs = again.replay.agent.obs[10]
        assert np.allclose(ExportedPolicy.load(path)(obs), again.agent.act(obs), atol=1e-5)
        rows = (tmp_path / "metrics.csv").read_text().splitlines()
        assert "temperature" in rows[0] and again.counters.step >= 400
    finally:
        again.close()
    with pytest.raises(Exception, match="different configuration"):
        Trainer(run_config(tc, dc, gc, ec, sac=dataclasses.replace(sc, utd=3)), tmp_path).load_checkpoint()
