"""Guided DDPG (Lillicrap et al.), the default learner, on the CPU: read top to bottom.

`DDPGConfig` says what can be set (Table I of the paper where it gives a value); `DDPG.update` is one
minibatch: a critic step towards a clipped double-Q target (Fujimoto et al. 2018: the minimum of two target
critics, each with LayerNorm in its hidden layers as RLPD's critics have; both ours, not in the paper), then an
actor step on the deterministic policy gradient of the first
critic plus a behaviour-cloning term on the batch's expert (ζ = 1) samples (TD3+BC-style, ours), then the
Polyak updates of the target networks. Evaluations and the exported policy use the target actor — the
τ-average of the actor's weights — which does not wander from one update to the next as the online actor
does under noisy labels; exploration uses the online actor plus Gaussian noise. The networks (the anchored
actor, the critic pair) are in `networks`; the update's arithmetic, one compiled function of tensors, in
`ddpg_update`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, ClassVar

import numpy as np
import torch

from mrguide.config import ConfigError, Range, check_ranges
from mrguide.policies.ddpg_update import AdamMoments, Networks, Rates, run_update, td_target
from mrguide.policies.networks import Actor, CriticEnsemble, ObsScaler
from mrguide.policies.replay_buffer import Batch, TaggedReplay


@dataclass(frozen=True)
class DDPGConfig:
    """[ddpg] of a training config."""

    hidden: tuple[int, ...] = (96, 96)  # ours: the width that met the convergence and the speed targets
    lr_actor: Annotated[float, Range(1e-8, 1.0)] = 5e-4  # Table I
    lr_critic: Annotated[float, Range(1e-8, 1.0)] = 5e-4  # Table I
    gamma: Annotated[float, Range(0.0, 1.0)] = 0.99  # Table I
    tau: Annotated[float, Range(1e-6, 1.0)] = 0.005  # soft target update rate (ours)
    #: std of the Gaussian action noise, normalized units (ours: 0.1 let a learner that had converged fall back
    #: on a 5 mm seal; docs/results/README.md, "A person's error model over the live protocol")
    exploration_noise: Annotated[float, Range(0.0, 2.0)] = 0.05
    #: Weight of the behaviour-cloning term on the expert (ζ = 1) samples of each batch, with the Q term
    #: normalized by its mean magnitude as in TD3+BC (Fujimoto & Gu 2021). Not in the paper; 0 gives plain
    #: DDPG's actor step. It acts only on expert samples, so a run without guidance is unaffected.
    bc_weight: Annotated[float, Range(0.0, 1e4)] = 20.0

    def __post_init__(self) -> None:
        if not self.hidden or any(
            isinstance(h, bool) or not isinstance(h, int) or not 1 <= h <= 4096 for h in self.hidden
        ):
            raise ConfigError(f"ddpg.hidden = {list(self.hidden)!r}: expected one or more layer widths in [1, 4096]")
        check_ranges(self, "ddpg")


class DDPG:
    """Actor-critic with target networks; `update` takes one minibatch."""

    #: What `act` reads: the online actor (exploring) and the target actor (evaluated).
    acting_modules: ClassVar[tuple[str, ...]] = ("actor", "actor_target")

    def __init__(self, obs_offset: np.ndarray, obs_scale: np.ndarray, act_dim: int, cfg: DDPGConfig, seed: int = 0):
        self.cfg = cfg
        self.act_dim = act_dim
        torch.manual_seed(seed)

        def scaler() -> ObsScaler:
            return ObsScaler(obs_offset, obs_scale)

        self.actor = Actor(scaler(), act_dim, cfg.hidden)
        self.critic = CriticEnsemble(scaler(), act_dim, cfg.hidden, 2)
        self.actor_target = Actor(scaler(), act_dim, cfg.hidden)
        self.critic_target = CriticEnsemble(scaler(), act_dim, cfg.hidden, 2)
        self.actor_target.load_state_dict(self.actor.state_dict())
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.nets = Networks(self.actor, self.critic, self.actor_target, self.critic_target)
        self.actor_moments = AdamMoments.zeros_like(list(self.actor.parameters()))
        self.critic_moments = AdamMoments.zeros_like(list(self.critic.parameters()))
        self.rates = Rates(cfg.gamma, cfg.tau, cfg.lr_actor, cfg.lr_critic, cfg.bc_weight)
        self.updates = 0  # updates so far

    @property
    def policy_actor(self) -> Actor:
        """The actor that is evaluated and exported: the target actor."""
        return self.actor_target

    @torch.no_grad()
    def act(self, obs: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """Without `rng`, the evaluated policy's deterministic action (`policy_actor`); with it, the online
        actor's action plus Gaussian exploration noise. Clipped to [-1, 1]."""
        actor = self.actor if rng is not None else self.policy_actor
        a = actor(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0)).squeeze(0).numpy()
        if rng is not None:
            a = a + rng.normal(0.0, self.cfg.exploration_noise, a.shape)
        return np.clip(a, -1.0, 1.0).astype(np.float32)

    def learn(
        self, replay: TaggedReplay, lam: float, batch_size: int, rng: np.random.Generator
    ) -> tuple[dict[str, float], float]:
        """One environment step's learning: one update on a minibatch mixed by λ (Eq. 9); (statistics, expert share)."""
        batch = replay.sample(batch_size, lam, rng)
        return self.update(batch), batch.expert_ratio

    #: Keys of `update`'s statistics.
    CRITIC_STATS = ("critic_loss", "q_mean", "q_max")
    ACTOR_STATS = ("actor_loss", "actor_q", "bc_loss")

    def update(self, batch: Batch) -> dict[str, float]:
        """One critic step, one actor step and the soft target updates.

        Returns the update's statistics (gathered into floats with one conversion):
        - critic_loss: the critics' summed MSE to the TD target (the loss the critic step minimizes);
        - q_mean, q_max: mean and max over the batch of Q_φ1(s, a) for the stored actions, as evaluated
          for this step (before the critic step);
        - actor_loss = actor_q + bc_weight · bc_loss, where actor_q is the Q term (−mean Q_φ1(s, μ(s)),
          divided by the batch's mean |Q| when the BC term is on) and bc_loss the mean `bc_error` on the
          batch's expert (ζ = 1) samples; bc_loss is 0 when the batch holds none (always, without guidance)
          or bc_weight is 0.
        """
        expert = torch.as_tensor(batch.expert, dtype=torch.float32)
        tensors = tuple(torch.as_tensor(x) for x in (batch.obs, batch.act, batch.rew, batch.next_obs, batch.done))
        stats = run_update(self.nets, (self.actor_moments, self.critic_moments), self.rates, (*tensors, expert))
        self.updates += 1
        return dict(zip(self.CRITIC_STATS + self.ACTOR_STATS, stats.tolist()))

    def td_target(self, rew: torch.Tensor, next_obs: torch.Tensor, done: torch.Tensor) -> torch.Tensor:
        """The critics' TD target for a batch (`ddpg_update.td_target`)."""
        return td_target(self.nets, self.cfg.gamma, rew, next_obs, done)

    def state_dict(self) -> dict:
        return {
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "actor_target": self.actor_target.state_dict(),
            "critic_target": self.critic_target.state_dict(),
            "actor_opt": self.actor_moments.state_dict(),
            "critic_opt": self.critic_moments.state_dict(),
            "updates": self.updates,
        }

    def load_state_dict(self, state: dict) -> None:
        self.actor.load_state_dict(state["actor"])
        self.actor_target.load_state_dict(state["actor_target"])
        self.critic.load_state_dict(state["critic"])
        self.critic_target.load_state_dict(state["critic_target"])
        self.actor_moments.load_state_dict(state["actor_opt"])
        self.critic_moments.load_state_dict(state["critic_opt"])
        self.updates = state["updates"]
