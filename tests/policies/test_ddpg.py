"""DDPG update mechanics: every update steps critic, actor and targets; the critic pair; the BC term; config validation."""

import copy
import dataclasses

import numpy as np
import pytest
import torch

from mrguide.config import ConfigError
from mrguide.policies.ddpg import DDPG, DDPGConfig
from mrguide.policies.ddpg_update import GRIP_MARGIN, bc_error
from mrguide.policies.replay_buffer import TaggedReplay


def batches(n, size=32):
    rb = TaggedReplay(1000, 11, 4)
    rng = np.random.default_rng(0)
    for i in range(500):
        rb.add(rng.normal(size=11), rng.uniform(-1, 1, 4), -1.0, rng.normal(size=11), False, i % 3 == 0)
    return [rb.sample(size, 0.5, rng) for _ in range(n)]


def make(**cfg) -> DDPG:
    return DDPG(np.zeros(11), np.ones(11), 4, DDPGConfig(hidden=(16, 16), **cfg), seed=0)


def params(net):
    return [p.detach().clone() for p in net.parameters()]


def changed(before, net):
    return any(not torch.equal(a, b) for a, b in zip(before, net.parameters()))


def test_every_update_steps_the_critic_the_actor_and_both_targets():
    agent = DDPG(np.zeros(11), np.ones(11), 4, DDPGConfig(hidden=(16, 16)))
    for batch in batches(3):
        before = [params(n) for n in (agent.actor, agent.critic, agent.actor_target, agent.critic_target)]
        losses = agent.update(batch)
        assert all(
            changed(b, n) for b, n in zip(before, (agent.actor, agent.critic, agent.actor_target, agent.critic_target))
        )
        assert set(losses) == set(DDPG.CRITIC_STATS + DDPG.ACTOR_STATS)
    assert agent.state_dict()["updates"] == 3


def test_two_independently_initialized_critics():
    agent = DDPG(np.zeros(11), np.ones(11), 4, DDPGConfig(hidden=(16, 16)))
    q = agent.critic(torch.zeros(5, 11), torch.zeros(5, 4))
    assert q.shape == (2, 5) and not torch.equal(q[0], q[1])


def test_the_critics_normalize_every_hidden_layer():
    agent = DDPG(np.zeros(11), np.ones(11), 4, DDPGConfig(hidden=(16, 16)))
    assert [tuple(g.shape) for g in agent.critic.norm_gains] == [(2, 1, 16), (2, 1, 16)]
    obs, act = torch.randn(7, 11), torch.randn(7, 4)
    with torch.no_grad():  # a first layer 1000 times larger changes nothing after its norm
        q = agent.critic(obs, act)
        agent.critic.weights[0].mul_(1000.0)
        agent.critic.biases[0].mul_(1000.0)
        assert torch.allclose(agent.critic(obs, act), q, atol=1e-4)
        agent.critic.weights[1].mul_(1000.0)  # the second layer's norm too
        agent.critic.biases[1].mul_(1000.0)
        assert torch.allclose(agent.critic(obs, act), q, atol=1e-4)
        agent.critic.weights[2].mul_(2.0)  # but not the output layer
        assert not torch.allclose(agent.critic(obs, act), q, atol=1e-4)


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
    torch.manual_seed(5)
    for b in bs[3:]:
        c.update(b)
    assert all(torch.equal(p, q) for p, q in zip(a.actor.parameters(), c.actor.parameters()))


@pytest.mark.parametrize("bad", [{"hidden": ()}, {"tau": 0.0}, {"bc_weight": -1.0}])
def test_bad_config_refused(bad):
    with pytest.raises(ConfigError):
        DDPGConfig(**bad)


def one_batch(expert_share, size=64, seed=0):
    """A batch whose expert share is `expert_share` (pools of random transitions, ζ = 1 every third)."""
    rb = TaggedReplay(1000, 11, 4)
    rng = np.random.default_rng(seed)
    for i in range(300):
        rb.add(rng.normal(size=11), rng.uniform(-1, 1, 4), rng.normal(), rng.normal(size=11), i % 7 == 0, i % 3 == 0)
    return rb.sample(size, expert_share, rng)


def test_update_statistics_agree_with_a_direct_evaluation_on_the_same_batch():
    cfg = DDPGConfig(hidden=(16, 16))
    agent = DDPG(np.zeros(11), np.ones(11), 4, cfg, seed=3)
    for b in batches(5):  # away from the initialization
        agent.update(b)
    batch = one_batch(0.5)
    assert batch.expert.any() and not batch.expert.all()
    before = copy.deepcopy(agent)
    stats = agent.update(batch)
    assert set(stats) == {"critic_loss", "q_mean", "q_max", "actor_loss", "actor_q", "bc_loss"}
    assert all(np.isfinite(v) and isinstance(v, float) for v in stats.values())
    obs, act = torch.as_tensor(batch.obs), torch.as_tensor(batch.act)
    with torch.no_grad():
        q = before.critic(obs, act)  # the critic as the update found it
        next_obs = torch.as_tensor(batch.next_obs)
        next_q = before.critic_target(next_obs, before.actor_target(next_obs)).min(0).values
        target = torch.as_tensor(batch.rew) + cfg.gamma * (1 - torch.as_tensor(batch.done)) * next_q
        pi = before.actor(obs)  # the actor before its step, against the critic after its step
        q_pi = agent.critic(obs, pi)[0]
    expert = torch.as_tensor(batch.expert)
    assert stats["q_mean"] == pytest.approx(q[0].mean().item(), rel=1e-6)
    assert stats["q_max"] == pytest.approx(q[0].max().item(), rel=1e-6)
    assert stats["q_max"] > stats["q_mean"]
    assert stats["critic_loss"] == pytest.approx(((q - target) ** 2).mean(1).sum().item(), rel=1e-5)
    pe, ae = pi[expert], act[expert]
    grip = torch.relu(GRIP_MARGIN - torch.sign(ae[:, 3]) * pe[:, 3]) ** 2  # a hinge on the gripper command
    bc = (((pe[:, :3] - ae[:, :3]) ** 2).sum(-1) + grip).mean().item()
    assert stats["bc_loss"] == pytest.approx(bc, rel=1e-5) and bc > 0
    assert stats["actor_q"] == pytest.approx((-q_pi.mean() / (q_pi.abs().mean() + 1e-6)).item(), rel=1e-5)
    assert stats["actor_loss"] == pytest.approx(stats["actor_q"] + cfg.bc_weight * stats["bc_loss"], rel=1e-6)


def test_bc_gripper_term_asks_for_the_right_side_of_zero_by_the_margin_and_no_more():
    """A gripper output already beyond the margin on the expert's side gets no pull (so tanh never saturates); the
    wrong side or too close to 0 is pulled; the position part is a plain squared error."""
    act = torch.tensor([[0.1, 0.2, 0.3, 1.0], [0.1, 0.2, 0.3, -1.0], [0.1, 0.2, 0.3, 1.0], [0.1, 0.2, 0.3, -1.0]])
    pi = torch.tensor(
        [[0.1, 0.2, 0.3, 0.7], [0.1, 0.2, 0.3, -0.9], [0.1, 0.2, 0.3, 0.2], [0.2, 0.2, 0.3, 0.4]], requires_grad=True
    )
    err = bc_error(pi, act)
    assert err[:2].tolist() == [0.0, 0.0]
    assert err[2].item() == pytest.approx((GRIP_MARGIN - 0.2) ** 2)
    assert err[3].item() == pytest.approx(0.1**2 + (GRIP_MARGIN + 0.4) ** 2)
    err.sum().backward()
    assert pi.grad[0].abs().sum() == 0 and pi.grad[2, 3] < 0 and pi.grad[3, 3] > 0


def test_bc_term_is_zero_without_expert_samples_and_positive_with_them():
    agent = DDPG(np.zeros(11), np.ones(11), 4, DDPGConfig(hidden=(16, 16)), seed=0)
    no_expert = one_batch(0.0)
    assert not no_expert.expert.any()
    stats = agent.update(no_expert)
    assert stats["bc_loss"] == 0.0 and stats["actor_loss"] == stats["actor_q"]  # plain DDPG's actor loss: -mean Q
    assert agent.update(one_batch(0.5, seed=1))["bc_loss"] > 0
    off = DDPG(np.zeros(11), np.ones(11), 4, DDPGConfig(hidden=(16, 16), bc_weight=0.0), seed=0)
    assert off.update(one_batch(0.5, seed=1))["bc_loss"] == 0.0


def test_td_target_takes_the_minimum_of_the_two_target_critics_and_stops_at_terminals():
    agent = make()
    rng = np.random.default_rng(0)
    next_obs = torch.as_tensor(rng.uniform(-1, 1, (64, 11)), dtype=torch.float32)
    rew = torch.as_tensor(rng.normal(size=64), dtype=torch.float32)
    done = torch.as_tensor((np.arange(64) % 2).astype(np.float32))
    with torch.no_grad():
        q_pair = agent.critic_target(next_obs, agent.actor_target(next_obs))
    assert not torch.allclose(q_pair[0], q_pair[1])  # two different target critics
    target = agent.td_target(rew, next_obs, done)
    expected = rew + agent.cfg.gamma * (1 - done) * torch.minimum(q_pair[0], q_pair[1])
    assert torch.allclose(target, expected)
    assert torch.equal(target[done == 1], rew[done == 1])  # terminated: no bootstrap


def test_a_target_clamped_below_the_box_still_learns():
    """The part's centre lies below the box floor, so the actor starts with its targets clamped there; its
    straight-through clamp passes the gradient, and cloning lifts the target to the label (with a plain clamp
    the height got no gradient and stayed on the floor: the approach height was never learned)."""
    from mrguide.policies.networks import obs_scaling
    from mrguide.robot import load_robot

    ws = load_robot().workspace
    agent = DDPG(*obs_scaling(ws), 4, DDPGConfig(hidden=(16, 16)), seed=0)
    obs = np.array(
        [0.5, 0.1, 0.2, -1.0, 0.0, 0.47, -0.05, -0.3, 0.57, 0.16, 0.02], dtype=np.float32
    )  # part 30 cm below
    label = np.concatenate([ws.to_normalized([0.47, -0.05, 0.13]), [-1.0]]).astype(np.float32)
    o, a = torch.as_tensor(obs[None]), torch.as_tensor(label[None])
    assert agent.actor(o)[0, 2].item() == -1.0  # clamped to the floor
    opt = torch.optim.Adam(agent.actor.parameters(), lr=1e-2)
    for _ in range(300):
        loss = ((agent.actor(o) - a) ** 2).sum()
        opt.zero_grad()
        loss.backward()
        opt.step()
    assert abs(ws.to_cartesian(agent.actor(o).detach().numpy()[0, :3])[2] - 0.13) < 0.005


def test_the_averaged_actor_is_evaluated_and_the_online_one_explores():
    agent = make()
    for b in batches(20):
        agent.update(b)  # the online actor moves; its target follows only by τ
    obs = np.random.default_rng(1).normal(size=(8, 11)).astype(np.float32)
    with torch.no_grad():
        online, target = (net(torch.as_tensor(obs)).numpy() for net in (agent.actor, agent.actor_target))
    assert np.abs(online - target).max() > 1e-3
    evaluated = np.array([agent.act(o) for o in obs])
    assert np.allclose(evaluated, target, atol=1e-6) and agent.policy_actor is agent.actor_target
    explored = np.array([agent.act(o, np.random.default_rng(0)) for o in obs])
    assert not np.allclose(explored, online, atol=1e-3)  # exploration noise on the online actor's action
    agent.cfg = dataclasses.replace(agent.cfg, exploration_noise=0.0)
    assert np.allclose([agent.act(o, np.random.default_rng(0)) for o in obs], online, atol=1e-6)
