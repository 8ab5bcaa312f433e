"""DDPG's minibatch update as one function of tensors, compiled by TorchInductor into one graph.

`update_step` is the whole of `DDPG.update`'s arithmetic: the clipped double-Q target, the critic step, the
actor step (deterministic policy gradient plus the behaviour-cloning term), the two Adam steps and the Polyak
averaging of the targets. The gradients come from `torch.func.grad` and Adam's arithmetic is written out
(`adam_`, that of `torch.optim.Adam` without weight decay), so that nothing in it calls back into Python: compiled
whole, one update of the default learner costs about half the eager version on this project's machines
(`benchmarks/update.py`). The eager version runs where the compiler cannot (`run_update`).
"""

from __future__ import annotations

import functools
import logging
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import torch
from torch import nn
from torch.func import functional_call, grad

from mrguide.policies.networks import Actor, CriticEnsemble

log = logging.getLogger(__name__)

#: The behaviour-cloning term asks the gripper output for the expert's side of 0 by at least this much, no more:
#: pulling a tanh output towards a label of exactly ±1 saturates it, and a saturated gripper output never
#: learns again (ours; seen when early noisy release marks had taught "vacuum on" at the goal).
GRIP_MARGIN = 0.5
#: torch.optim.Adam's defaults, which the paper's Table I does not change.
BETAS = (0.9, 0.999)
EPS = 1e-8


class Networks(NamedTuple):
    """The four networks an update reads and writes."""

    actor: Actor
    critic: CriticEnsemble
    actor_target: Actor
    critic_target: CriticEnsemble


class Rates(NamedTuple):
    """The update's constants (from `DDPGConfig`)."""

    gamma: float
    tau: float
    lr_actor: float
    lr_critic: float
    bc_weight: float


@dataclass
class AdamMoments:
    """Adam's state for one network: the first and second moments per parameter and the step count."""

    exp_avg: list[torch.Tensor]
    exp_avg_sq: list[torch.Tensor]
    step: torch.Tensor  # float32 scalar

    @classmethod
    def zeros_like(cls, params: list[torch.Tensor]) -> AdamMoments:
        return cls(
            [torch.zeros_like(p) for p in params],
            [torch.zeros_like(p) for p in params],
            torch.zeros((), dtype=torch.float32),
        )

    def state_dict(self) -> dict:
        return {"exp_avg": self.exp_avg, "exp_avg_sq": self.exp_avg_sq, "step": self.step}

    def load_state_dict(self, state: dict) -> None:
        """Copy `state` in place (the compiled update holds these tensors); ValueError if it does not fit."""
        if not {"exp_avg", "exp_avg_sq", "step"} <= set(state):
            raise ValueError("the optimizer state is not this version's (exp_avg, exp_avg_sq, step)")
        for mine, theirs in ((self.exp_avg, state["exp_avg"]), (self.exp_avg_sq, state["exp_avg_sq"])):
            if len(mine) != len(theirs) or any(a.shape != b.shape for a, b in zip(mine, theirs)):
                raise ValueError("the optimizer state does not fit these networks")
            for a, b in zip(mine, theirs):
                a.copy_(b)
        self.step.copy_(state["step"])


@torch.no_grad()
def adam_(params: list[torch.Tensor], grads: list[torch.Tensor], moments: AdamMoments, lr: float) -> None:
    """One Adam step in place, `torch.optim.Adam`'s arithmetic (bias-corrected moments, ε outside the root)."""
    moments.step.add_(1.0)
    bias1 = 1.0 - BETAS[0] ** moments.step
    bias2_sqrt = (1.0 - BETAS[1] ** moments.step).sqrt()
    for p, g, m, v in zip(params, grads, moments.exp_avg, moments.exp_avg_sq):
        m.lerp_(g, 1.0 - BETAS[0])
        v.mul_(BETAS[1]).addcmul_(g, g, value=1.0 - BETAS[1])
        p.sub_(lr / bias1 * m / (v.sqrt() / bias2_sqrt + EPS))


def bc_error(pi: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
    """Per sample: the squared error of the target position plus a squared hinge on the gripper command."""
    grip = torch.relu(GRIP_MARGIN - torch.sign(act[..., 3]) * pi[..., 3]) ** 2
    return ((pi[..., :3] - act[..., :3]) ** 2).sum(-1) + grip


@torch.no_grad()
def td_target(
    nets: Networks, gamma: float, rew: torch.Tensor, next_obs: torch.Tensor, done: torch.Tensor
) -> torch.Tensor:
    """r + γ (1 − done) min_i Q'_i(s', μ'(s')): no bootstrap past a terminal state (done = terminated,
    not truncated), the minimum over the two target critics."""
    next_q = nets.critic_target(next_obs, nets.actor_target(next_obs)).min(0).values
    return rew + gamma * (1.0 - done) * next_q


def _critic_loss(
    params: dict[str, torch.Tensor],
    critic: CriticEnsemble,
    obs: torch.Tensor,
    act: torch.Tensor,
    target: torch.Tensor,
) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor]]:
    """The critics' summed MSE to the TD target; aux: (the loss, Q_φ1(s, a)) without gradients."""
    q = functional_call(critic, params, (obs, act))
    loss = nn.functional.mse_loss(q, target.expand_as(q)) * q.shape[0]  # sum of the members' losses
    return loss, (loss.detach(), q[0].detach())


def _actor_loss(
    params: dict[str, torch.Tensor],
    nets: Networks,
    obs: torch.Tensor,
    act: torch.Tensor,
    expert: torch.Tensor,
    bc_weight: float,
) -> tuple[torch.Tensor, tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
    """−Q_φ1(s, μ(s)), normalized by the batch's mean |Q| when the BC term acts, plus bc_weight × the mean
    `bc_error` on the expert (ζ = 1) samples; aux: (the loss, the Q term, the BC loss) without gradients."""
    pi = functional_call(nets.actor, params, (obs,))
    q_pi = nets.critic(obs, pi, slice(0, 1)).squeeze(0)  # the actor follows the first critic (as TD3)
    n_expert = expert.sum()
    with_bc = n_expert > 0 if bc_weight > 0 else torch.zeros((), dtype=torch.bool)
    bc_loss = torch.where(with_bc, (bc_error(pi, act) * expert).sum() / n_expert.clamp(min=1.0), 0.0)
    q_term = torch.where(with_bc, -q_pi.mean() / (q_pi.abs().mean().detach() + 1e-6), -q_pi.mean())
    loss = q_term + bc_weight * bc_loss
    return loss, (loss.detach(), q_term.detach(), bc_loss.detach())


def update_step(
    nets: Networks,
    moments: tuple[AdamMoments, AdamMoments],
    rates: Rates,
    batch: tuple[torch.Tensor, ...],
) -> torch.Tensor:
    """One critic step, one actor step (against the stepped critic) and the soft target updates, in place.
    `moments` are the actor's and the critic's; `batch` is (obs, act, rew, next_obs, done, expert as 0/1).
    Returns (critic loss, mean and max of Q_φ1(s, a) before the step, actor loss, Q term, BC loss)."""
    obs, act, rew, next_obs, done, expert = batch
    target = td_target(nets, rates.gamma, rew, next_obs, done)
    critic_params: dict[str, torch.Tensor] = dict(nets.critic.named_parameters())
    grads, (critic_loss, q1) = grad(_critic_loss, has_aux=True)(critic_params, nets.critic, obs, act, target)
    adam_(list(critic_params.values()), list(grads.values()), moments[1], rates.lr_critic)
    actor_params: dict[str, torch.Tensor] = dict(nets.actor.named_parameters())
    grads, actor_stats = grad(_actor_loss, has_aux=True)(actor_params, nets, obs, act, expert, rates.bc_weight)
    adam_(list(actor_params.values()), list(grads.values()), moments[0], rates.lr_actor)
    with torch.no_grad():
        for net, tgt in ((nets.actor, nets.actor_target), (nets.critic, nets.critic_target)):
            for p, t in zip(net.parameters(), tgt.parameters()):
                t.lerp_(p, rates.tau)
        return torch.stack([critic_loss, q1.mean(), q1.max(), *actor_stats])


_compiler_works = True


@functools.cache
def _compiled_step() -> Callable[..., torch.Tensor]:
    """`update_step` wrapped by torch.compile, made at the first compiled update (TorchInductor builds it then)."""
    return torch.compile(update_step, fullgraph=True)


def _compile_disabled() -> bool:
    """Whether torch.compile is off: ``TORCH_COMPILE_DISABLE=1``, as torch reads it, or torch._dynamo's config.

    The compiler's package (torch._dynamo, 1.5 s of CPU) is imported only where the update may be compiled: a
    process that the environment keeps eager (the tests' learner processes, workers and CLI runs) starts without it.
    """
    if "torch._dynamo" not in sys.modules and os.environ.get("TORCH_COMPILE_DISABLE", "0") == "1":
        return True
    import torch._dynamo

    return bool(torch._dynamo.config.disable)


def update_build() -> str:
    """How this process runs the update, for a run's record: compiled, or eager where torch.compile is disabled
    (``TORCH_COMPILE_DISABLE=1``, the comparison the results page makes) or has failed."""
    if _compile_disabled():
        return "eager (torch.compile disabled)"
    return "compiled" if _compiler_works else "eager (TorchInductor failed)"


def run_update(
    nets: Networks, moments: tuple[AdamMoments, AdamMoments], rates: Rates, batch: tuple[torch.Tensor, ...]
) -> torch.Tensor:
    """`update_step`, compiled; eagerly (the same arithmetic, slower) where torch.compile is disabled or once
    TorchInductor has failed to build it, e.g. with no C++ compiler on the machine (said once, in the log)."""
    global _compiler_works
    if _compiler_works and not _compile_disabled():
        try:
            return _compiled_step()(nets, moments, rates, batch)
        except torch._dynamo.exc.BackendCompilerFailed as exc:
            _compiler_works = False
            log.warning("the DDPG update runs uncompiled, about twice as slow: TorchInductor failed (%s)", exc)
    return update_step(nets, moments, rates, batch)
