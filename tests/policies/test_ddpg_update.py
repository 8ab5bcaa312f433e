"""The compiled DDPG update: the same arithmetic as the eager one, Adam's as torch's, an eager fallback.

The other tests run the update eagerly (tests/conftest.py sets TORCH_COMPILE_DISABLE); these turn the compiler on.
"""

import copy
import logging

import numpy as np
import pytest
import torch

from mrguide.policies import ddpg_update
from mrguide.policies.ddpg import DDPG, DDPGConfig
from mrguide.policies.ddpg_update import AdamMoments, adam_, update_step
from mrguide.policies.replay_buffer import TaggedReplay


def agent_and_batches(n: int) -> tuple[DDPG, list]:
    rb = TaggedReplay(1000, 11, 4)
    rng = np.random.default_rng(0)
    for i in range(300):
        rb.add(rng.normal(size=11), rng.uniform(-1, 1, 4), rng.normal(), rng.normal(size=11), i % 7 == 0, i % 3 == 0)
    return DDPG(np.zeros(11), np.ones(11), 4, DDPGConfig(hidden=(16, 16)), seed=0), [
        rb.sample(64, 0.3, rng) for _ in range(n)
    ]


def tensors(batch) -> tuple[torch.Tensor, ...]:
    arrays = (batch.obs, batch.act, batch.rew, batch.next_obs, batch.done)
    return (*(torch.as_tensor(x) for x in arrays), torch.as_tensor(batch.expert, dtype=torch.float32))


@pytest.fixture
def compiler_on():
    """torch.compile enabled, whatever the environment says (its own patch: monkeypatch's undo would not do)."""
    with torch._dynamo.config.patch(disable=False):
        yield


def test_the_compiled_update_computes_what_the_eager_one_does(compiler_on):
    assert ddpg_update.update_build() == "compiled"
    compiled, batches = agent_and_batches(4)
    eager = copy.deepcopy(compiled)
    eager.nets = ddpg_update.Networks(eager.actor, eager.critic, eager.actor_target, eager.critic_target)
    for batch in batches:
        stats = compiled.update(batch)  # through run_update: the compiled step
        expected = update_step(eager.nets, (eager.actor_moments, eager.critic_moments), eager.rates, tensors(batch))
        assert list(stats.values()) == pytest.approx(expected.tolist(), rel=1e-4, abs=1e-5)
    for a, b in zip(compiled.nets, eager.nets):
        for p, q in zip(a.parameters(), b.parameters()):
            assert torch.allclose(p, q, rtol=1e-4, atol=1e-5)
    assert compiled.updates == 4 and compiled.critic_moments.step.item() == eager.critic_moments.step.item() == 4


def test_adam_is_torch_adams_arithmetic():
    torch.manual_seed(0)
    ours = [torch.randn(5, 3), torch.randn(3)]
    theirs = [p.clone().requires_grad_() for p in ours]
    opt = torch.optim.Adam(theirs, lr=1e-2)
    moments = AdamMoments.zeros_like(ours)
    for _ in range(5):
        grads = [torch.randn_like(p) for p in ours]
        adam_(ours, grads, moments, 1e-2)
        for p, g in zip(theirs, grads):
            p.grad = g.clone()
        opt.step()
    for p, q in zip(ours, theirs):
        assert torch.allclose(p, q.detach(), rtol=1e-6, atol=1e-7)
    assert moments.step.item() == 5


def test_a_checkpointed_optimizer_state_of_another_shape_or_version_is_refused():
    moments = AdamMoments.zeros_like([torch.zeros(3)])
    with pytest.raises(ValueError, match="does not fit"):
        moments.load_state_dict(AdamMoments.zeros_like([torch.zeros(4)]).state_dict())
    with pytest.raises(ValueError, match="not this version"):
        moments.load_state_dict({"state": {}, "param_groups": []})  # torch.optim.Adam's state_dict


def test_without_a_compiler_the_update_runs_eagerly_and_says_so(compiler_on, monkeypatch, caplog):
    agent, batches = agent_and_batches(1)
    torch._dynamo.reset()  # forget the builds this process made: the next call compiles
    monkeypatch.setattr(ddpg_update, "_compiler_works", True)
    before = [p.detach().clone() for p in agent.actor.parameters()]
    no_compiler = {"cpp.cxx": ("/nonexistent/g++",), "fx_graph_cache": False}  # and no cached build to load
    with torch._inductor.config.patch(no_compiler), caplog.at_level(logging.WARNING, "mrguide.policies.ddpg_update"):
        stats = agent.update(batches[0])
        agent.update(batches[0])
    assert all(np.isfinite(v) for v in stats.values()) and agent.updates == 2
    assert any(not torch.equal(a, b) for a, b in zip(before, agent.actor.parameters()))
    ours = [r.message for r in caplog.records if r.name == "mrguide.policies.ddpg_update"]
    assert len(ours) == 1 and "uncompiled" in ours[0] and "No working C++ compiler" in ours[0]  # said once, why
    assert ddpg_update._compiler_works is False


def test_with_torch_compile_disabled_the_update_runs_eagerly_and_the_run_says_so(compiler_on, monkeypatch):
    """TORCH_COMPILE_DISABLE=1 (the eager comparison runs of the results page) trains and is named in run.json."""
    agent, batches = agent_and_batches(1)
    monkeypatch.setattr(ddpg_update, "_compiler_works", True)
    with torch._dynamo.config.patch(disable=True):  # its own patch: monkeypatch's undo would hide the option
        assert ddpg_update.update_build() == "eager (torch.compile disabled)"
        stats = agent.update(batches[0])  # fullgraph=True would raise here without the check
    assert all(np.isfinite(v) for v in stats.values()) and agent.updates == 1
    assert ddpg_update.update_build() == "compiled"
