"""DDPG update mechanics: delayed actor steps, the critic pair, config validation."""

import copy

import numpy as np
import pytest
import torch

from mrguide.config import ConfigError
from mrguide.policies.ddpg import DDPG, DDPGConfig
from mrguide.policies.replay import TaggedReplay


def batches(n, size=32):
    rb = TaggedReplay(1000, 11, 4)
    rng = np.random.default_rng(0)
    for i in range(500):
        rb.add(rng.normal(size=11), rng.uniform(-1, 1, 4), -1.0, rng.normal(size=11), False, i % 3 == 0)
    return [rb.sample(size, 0.5, rng) for _ in range(n)]


def params(net):
    return [p.detach().clone() for p in net.parameters()]


def changed(before, net):
    return any(not torch.equal(a, b) for a, b in zip(before, net.parameters()))


def test_actor_and_targets_step_every_policy_delay_updates():
    agent = DDPG(np.zeros(11), np.ones(11), 4, DDPGConfig(hidden=(16, 16), policy_delay=3))
    for k, batch in enumerate(batches(6), start=1):
        actor, target, critic = params(agent.actor), params(agent.critic_target), params(agent.critic)
        losses = agent.update(batch)
        assert changed(critic, agent.critic)
        assert changed(actor, agent.actor) == (k % 3 == 0) == ("actor_loss" in losses)
        assert changed(target, agent.critic_target) == (k % 3 == 0)
    assert agent.state_dict()["updates"] == 6


def test_clipped_double_q_keeps_two_critics_and_plain_ddpg_one():
    two = DDPG(np.zeros(11), np.ones(11), 4, DDPGConfig(hidden=(16, 16)))
    one = DDPG(np.zeros(11), np.ones(11), 4, DDPGConfig(hidden=(16, 16), clipped_double_q=False))
    obs, act = torch.zeros(5, 11), torch.zeros(5, 4)
    assert two.critic(obs, act).shape == (2, 5) and one.critic(obs, act).shape == (1, 5)
    q = two.critic(obs, act)
    assert not torch.equal(q[0], q[1])  # independently initialized members


def test_update_state_round_trip_continues_identically():
    cfg = DDPGConfig(hidden=(16, 16))
    a = DDPG(np.zeros(11), np.ones(11), 4, cfg, seed=1)
    bs = batches(8)
    for b in bs[:3]:
        a.update(b)
    c = DDPG(np.zeros(11), np.ones(11), 4, cfg, seed=2)
    c.load_state_dict(copy.deepcopy(a.state_dict()))  # as through a checkpoint file: no shared tensors
    torch.manual_seed(5)
    for b in bs[3:]:
        a.update(b)
    torch.manual_seed(5)  # target smoothing draws from torch's RNG
    for b in bs[3:]:
        c.update(b)
    assert all(torch.equal(p, q) for p, q in zip(a.actor.parameters(), c.actor.parameters()))


@pytest.mark.parametrize("bad", [{"policy_delay": 0}, {"target_noise": -0.1}, {"target_noise_clip": -1.0}])
def test_bad_config_refused(bad):
    with pytest.raises(ConfigError):
        DDPGConfig(**bad)
