"""The peer learner: SAC as RLPD (Ball et al. 2023) and HIL-SERL use it, on the CPU.

Read top to bottom: `SACConfig` says what can be set (RLPD's values unless marked ours); `SAC.learn` is one
environment step's learning: `utd` critic steps, each on a fresh minibatch that is half expert and half agent
data (RLPD's symmetric sampling; the λ schedule of Eq. 11 is not used), then one actor step and one
temperature step. The critics are an ensemble with LayerNorm; the TD target takes the minimum over a random
pair of target critics and backs up the entropy; the actor maximizes the ensemble's mean Q. No
behaviour-cloning term: demonstrations are just off-policy data, stored with the action that was executed.

The policy is a tanh-Gaussian over the actor's MLP output y, through the same anchored head as DDPG's actor
(`networks.Actor`), so the deterministic policy (tanh of the mean) exports and deploys as DDPG's does.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, ClassVar

import numpy as np
import torch
from torch import nn

from mrguide.config import ConfigError, Range, check_number, check_ranges
from mrguide.policies.networks import Actor, CriticEnsemble, ObsScaler
from mrguide.policies.replay_buffer import TaggedReplay

LOG_STD_MIN, LOG_STD_MAX = -20.0, 2.0  # RLPD's clip of the log standard deviation
INITIAL_TEMPERATURE = 0.01  # HIL-SERL's temperature_init


@dataclass(frozen=True)
class SACConfig:
    """[sac] of a training config; used when train.learner = "sac"."""

    hidden: tuple[int, ...] = (
        128,
        128,
    )  # RLPD: 256; ours for the CPU (a 20k-step run at 256 takes ~20 min on one core)
    lr: Annotated[float, Range(1e-8, 1.0)] = 3e-4  # actor, critics and temperature (RLPD)
    gamma: Annotated[float, Range(0.0, 1.0)] = 0.99
    tau: Annotated[float, Range(1e-6, 1.0)] = 0.005
    n_critics: Annotated[int, Range(1, 100)] = 10  # RLPD: an ensemble of 10 ...
    n_min: int = 2  # ... whose TD target is the minimum over a random 2
    utd: Annotated[int, Range(1, 100)] = 2  # critic updates per environment step (RLPD's runs: 20; ours, for the CPU)
    #: share of every batch drawn from the expert pool (RLPD's offline_ratio)
    expert_fraction: Annotated[float, Range(0.0, 1.0)] = 0.5
    # of the policy over the actor's y ∈ [-1, 1]^4; ours (RLPD: -|A|/2 = -2, which holds the policy at about 0.15 in y,
    # 7 cm of target, on a task with a 13 mm seal margin: 0/10 converged; -10 is about 1 cm per axis; docs: results)
    target_entropy: Annotated[float, Range(-100.0, 100.0)] = -10.0

    def __post_init__(self) -> None:
        if not self.hidden or any(
            isinstance(h, bool) or not isinstance(h, int) or not 1 <= h <= 4096 for h in self.hidden
        ):
            raise ConfigError(f"sac.hidden = {list(self.hidden)!r}: expected one or more layer widths in [1, 4096]")
        check_ranges(self, "sac")
        check_number("sac.n_min", self.n_min, 1, self.n_critics, integer=True)


class GaussianActor(nn.Module):
    """π(a | s): y = tanh(u), u ~ N(μ(s), σ(s)), a = the head's action for y. `base` is an actor whose MLP
    gives μ; `log_std` reads the same trunk. The deterministic policy, base(s) = head(tanh(μ(s))), is what
    is evaluated and exported."""

    def __init__(self, base: Actor):
        super().__init__()
        self.base = base
        mean_layer = base.net[-2]
        assert isinstance(mean_layer, nn.Linear)
        self.log_std = nn.Linear(mean_layer.in_features, mean_layer.out_features)

    def sample(self, obs: torch.Tensor, eps: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(action, log π) for standard-normal `eps`; log π is that of y (the head is affine in y but for the box clamp)."""
        h = self.base.net[:-2](self.base.inputs(obs))
        mean = self.base.net[-2](h)
        log_std = self.log_std(h).clamp(LOG_STD_MIN, LOG_STD_MAX)
        u = mean + log_std.exp() * eps
        y = torch.tanh(u)
        gauss = -0.5 * eps.pow(2) - log_std - 0.5 * np.log(2 * np.pi)
        squash = 2.0 * (np.log(2.0) - u - nn.functional.softplus(-2.0 * u))  # log(1 − tanh(u)²), stable
        return self.base.output(obs, y), (gauss - squash).sum(-1)


class SAC:
    """Soft actor-critic with a LayerNorm critic ensemble; `learn` is one environment step's updates."""

    CRITIC_STATS = ("critic_loss", "q_mean", "q_max")
    ACTOR_STATS = ("actor_loss", "temperature", "entropy")
    #: What `act` reads: the Gaussian actor, its deterministic base included.
    acting_modules: ClassVar[tuple[str, ...]] = ("actor",)

    def __init__(self, obs_offset: np.ndarray, obs_scale: np.ndarray, act_dim: int, cfg: SACConfig, seed: int = 0):
        self.cfg = cfg
        self.act_dim = act_dim
        torch.manual_seed(seed)

        def scaler() -> ObsScaler:
            return ObsScaler(obs_offset, obs_scale)

        self.actor = GaussianActor(Actor(scaler(), act_dim, cfg.hidden))
        self.critic = CriticEnsemble(scaler(), act_dim, cfg.hidden, cfg.n_critics)
        self.critic_target = CriticEnsemble(scaler(), act_dim, cfg.hidden, cfg.n_critics)
        self.critic_target.load_state_dict(self.critic.state_dict())
        # the temperature starts at 0.01 as in HIL-SERL (RLPD: 1.0, tuned for million-step runs; at this 20k-step
        # budget an entropy bonus of that size keeps the policy near uniform)
        self.log_temperature = torch.tensor(float(np.log(INITIAL_TEMPERATURE)), requires_grad=True)
        self.target_entropy = cfg.target_entropy
        self.actor_params = list(self.actor.parameters())
        self.actor_opt = torch.optim.Adam(self.actor_params, lr=cfg.lr, fused=True)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), lr=cfg.lr, fused=True)
        self.temperature_opt = torch.optim.Adam([self.log_temperature], lr=cfg.lr)
        self.updates = 0  # critic steps so far
        self._soft: tuple[list[torch.Tensor], list[torch.Tensor]] = (
            list(self.critic.parameters()),
            list(self.critic_target.parameters()),
        )

    @property
    def policy_actor(self) -> Actor:
        """The deterministic actor (tanh of the mean) that is evaluated and exported."""
        return self.actor.base

    @torch.no_grad()
    def act(self, obs: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """Without `rng` the deterministic action; with it a sample of π (its noise from `rng`)."""
        o = torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0)
        if rng is None:
            a = self.actor.base(o)
        else:
            a, _ = self.actor.sample(o, torch.as_tensor(rng.normal(size=(1, self.act_dim)), dtype=torch.float32))
        return np.clip(a.squeeze(0).numpy(), -1.0, 1.0).astype(np.float32)

    def learn(
        self, replay: TaggedReplay, lam: float, batch_size: int, rng: np.random.Generator
    ) -> tuple[dict[str, float], float]:
        """`utd` critic steps and one actor and temperature step; (statistics, realized expert share). `lam` unused."""
        n_expert = round(self.cfg.expert_fraction * batch_size)
        stats: list[torch.Tensor] = []
        for _ in range(self.cfg.utd):
            batch = replay.sample_split(batch_size, n_expert, rng)
            stats = self._critic_step(batch)
        obs = torch.as_tensor(batch.obs)
        stats = stats + self._actor_step(obs)
        with torch.no_grad():
            return dict(zip(self.CRITIC_STATS + self.ACTOR_STATS, torch.stack(stats).tolist())), batch.expert_ratio

    def _critic_step(self, batch) -> list[torch.Tensor]:
        obs, act, rew, next_obs, done = (
            torch.as_tensor(x) for x in (batch.obs, batch.act, batch.rew, batch.next_obs, batch.done)
        )
        with torch.no_grad():
            next_act, next_logp = self.actor.sample(next_obs, torch.randn(len(rew), self.act_dim))
            pair = torch.randperm(self.cfg.n_critics)[: self.cfg.n_min]
            next_q = self.critic_target(next_obs, next_act, pair).min(0).values
            target = rew + self.cfg.gamma * (1.0 - done) * (next_q - self.log_temperature.exp() * next_logp)
        q = self.critic(obs, act)
        loss = nn.functional.mse_loss(q, target.expand_as(q)) * q.shape[0]  # sum of the members' losses
        self.critic_opt.zero_grad()
        loss.backward()
        self.critic_opt.step()
        self.updates += 1
        with torch.no_grad():
            torch._foreach_lerp_(self._soft[1], self._soft[0], self.cfg.tau)
            return [loss, q.mean(), q.max()]

    def _actor_step(self, obs: torch.Tensor) -> list[torch.Tensor]:
        act, logp = self.actor.sample(obs, torch.randn(len(obs), self.act_dim))
        temperature = self.log_temperature.exp()
        loss = (temperature.detach() * logp - self.critic(obs, act).mean(0)).mean()
        for p, g in zip(self.actor_params, torch.autograd.grad(loss, self.actor_params)):
            p.grad = g
        self.actor_opt.step()
        entropy = -logp.detach().mean()
        temp_loss = temperature * (entropy - self.target_entropy)
        self.temperature_opt.zero_grad()
        temp_loss.backward()
        self.temperature_opt.step()
        return [loss.detach(), temperature.detach(), entropy]

    def state_dict(self) -> dict:
        return {
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "critic_target": self.critic_target.state_dict(),
            "log_temperature": self.log_temperature.detach().clone(),
            "actor_opt": self.actor_opt.state_dict(),
            "critic_opt": self.critic_opt.state_dict(),
            "temperature_opt": self.temperature_opt.state_dict(),
            "updates": self.updates,
        }

    def load_state_dict(self, state: dict) -> None:
        self.actor.load_state_dict(state["actor"])
        self.critic.load_state_dict(state["critic"])
        self.critic_target.load_state_dict(state["critic_target"])
        with torch.no_grad():
            self.log_temperature.copy_(state["log_temperature"])
        self.actor_opt.load_state_dict(state["actor_opt"])
        self.critic_opt.load_state_dict(state["critic_opt"])
        self.temperature_opt.load_state_dict(state["temperature_opt"])
        self.updates = state["updates"]
