"""DDPG (Lillicrap et al.) on the CPU: actor and critic MLPs, target networks, Gaussian exploration.

Defaults from Table I of the paper where it gives them (lr 5e-4, γ 0.99, batch 256, buffer 1e6);
hidden sizes, τ and the noise scale are ours. Two departures from plain DDPG are on by default: a
clipped double-Q target and a behaviour-cloning term on expert samples; TD3's other two changes
(target policy smoothing, delayed actor updates) are available and off. All switchable in `DDPGConfig`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from mrguide.config import ConfigError, check_number
from mrguide.deploy.policy import ANCHOR_KINDS
from mrguide.policies.replay import Batch, TaggedReplay
from mrguide.robot import Workspace

ACTOR_HEADS = ("absolute", "tcp_offset", *ANCHOR_KINDS)
#: φ above which the anchor actors see (and anchor_offset targets) the goal instead of the object: transport and release (φ = 3/5, 4/5, 1).
CARRY_PROGRESS = 0.5


@dataclass(frozen=True)
class DDPGConfig:
    hidden: tuple[int, ...] = (96, 96)  # ours: 9/10 seeds within 5k at 177 s per 20k-step run (128: 9/10, 205 s; 64: 7/10, 153 s)
    lr_actor: float = 5e-4  # Table I
    lr_critic: float = 5e-4  # Table I
    gamma: float = 0.99  # Table I
    tau: float = 0.005  # soft target update rate (ours)
    exploration_noise: float = 0.1  # std of the Gaussian action noise at the start, normalized units (ours)
    exploration_noise_final: float = 0.1  # ... decayed linearly to this by the end of training (ours)
    #: Clipped double-Q target (Fujimoto et al. 2018): min of two critics. Not in the paper (off = plain
    #: DDPG); on by default because without it guided runs collapsed after the expert intake closed.
    clipped_double_q: bool = True
    #: Weight of a behaviour-cloning term on the expert (ζ = 1) samples of each batch, with the Q term
    #: normalized by its mean magnitude as in TD3+BC (Fujimoto & Gu 2021). Not in the paper; 0 gives
    #: plain DDPG. It acts only on expert samples, so a run without guidance is unaffected, and it fades
    #: with λ_t as expert samples thin out of the batches.
    bc_weight: float = 20.0
    #: LayerNorm in every hidden layer of the critics (RLPD's critics; ours here).
    critic_layer_norm: bool = False
    #: Q-filter on the BC term (Nair et al. 2018): an expert sample is cloned only where the first critic
    #: rates its action above the actor's, Q_φ1(s, a^e) > Q_φ1(s, μ(s)), so a demonstration the critic has
    #: learned to beat stops pulling the actor. Not in the paper; off by default (ours, for noisy experts).
    q_filter: bool = False
    #: Target policy smoothing (TD3): clipped Gaussian noise of this std on the target action; 0 = DDPG.
    #: Off by default: with it and policy_delay = 2 fewer guided seeds converged by 5k (learning curves v4).
    target_noise: float = 0.0
    target_noise_clip: float = 0.5
    #: Actor and target networks are updated every `policy_delay` critic updates (TD3); 1 = DDPG.
    policy_delay: int = 1
    #: How the actor produces the target position. "absolute" (the paper's, default): the MLP sees the
    #: observation and outputs the normalized target. "tcp_offset" (ours): the MLP sees positions relative
    #: to the TCP (and the goal relative to the object) and outputs an offset of at most `max_offset` per
    #: axis that is added to the TCP, so the policy is equivariant to moving the whole scene in x and y.
    #: "phase_anchor" (ours): the same output, but the MLP sees only the TCP height, g, φ and the position of
    #: the phase's anchor relative to the TCP — the object in approach, grasp and lift, the goal in transport
    #: and release — so each phase is equivariant to moving its own anchor and blind to the other one.
    #: "anchor_offset" (ours): phase_anchor's input, but the offset is added to the anchor, not the TCP, so
    #: where the TCP strays off the expert's path the target stays put unless the MLP moves it (with the TCP
    #: as base, noisy labels on the expert's narrow path leave that feedback undetermined; Fig. 7).
    actor_head: str = "absolute"
    #: Evaluate and export the target actor — the Polyak average (τ) of the actor's weights — instead of the
    #: online actor, which under noisy expert labels wanders from one update to the next (Fig. 7); exploration
    #: still uses the online actor. Ours; off by default (every committed result used the online actor).
    act_with_target: bool = False
    max_offset: float = 0.5  # m, per axis, for the tcp_offset, phase_anchor and anchor_offset heads

    def __post_init__(self) -> None:
        if not self.hidden or any(isinstance(h, bool) or not isinstance(h, int) or not 1 <= h <= 4096 for h in self.hidden):
            raise ConfigError(f"ddpg.hidden = {list(self.hidden)!r}: expected one or more layer widths in [1, 4096]")
        check_number("ddpg.lr_actor", self.lr_actor, 1e-8, 1.0)
        check_number("ddpg.lr_critic", self.lr_critic, 1e-8, 1.0)
        check_number("ddpg.gamma", self.gamma, 0.0, 1.0)
        check_number("ddpg.tau", self.tau, 1e-6, 1.0)
        check_number("ddpg.exploration_noise", self.exploration_noise, 0.0, 2.0)
        check_number("ddpg.exploration_noise_final", self.exploration_noise_final, 0.0, 2.0)
        check_number("ddpg.bc_weight", self.bc_weight, 0.0, 1e4)
        check_number("ddpg.target_noise", self.target_noise, 0.0, 2.0)
        check_number("ddpg.target_noise_clip", self.target_noise_clip, 0.0, 2.0)
        check_number("ddpg.policy_delay", self.policy_delay, 1, 100, integer=True)
        if self.actor_head not in ACTOR_HEADS:
            raise ConfigError(f"ddpg.actor_head = {self.actor_head!r}: expected one of {', '.join(ACTOR_HEADS)}")
        check_number("ddpg.max_offset", self.max_offset, 0.01, 10.0, " m")


def obs_scaling(ws: Workspace) -> tuple[np.ndarray, np.ndarray]:
    """(offset, scale) mapping the observation's positions to the workspace's [-1, 1], g as is, φ to [-1, 1]."""
    centre, half = 0.5 * (ws.lo + ws.hi), 0.5 * (ws.hi - ws.lo)
    offset = np.concatenate([centre, [0.0, 0.5], centre, centre])
    scale = np.concatenate([1 / half, [1.0, 2.0], 1 / half, 1 / half])
    return offset, scale


def mlp(sizes: list[int], out_act: type[nn.Module] | None = None) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(nn.ReLU())
    if out_act is not None:
        layers.append(out_act())
    return nn.Sequential(*layers)


class ObsScaler(nn.Module):
    """Fixed affine input scaling x ↦ (x − offset) · scale, so positions in metres reach the first layer
    in about [-1, 1] (from the workspace box); not trained, folded into the first layer on export."""

    def __init__(self, offset: np.ndarray, scale: np.ndarray):
        super().__init__()
        self.register_buffer("offset", torch.as_tensor(offset, dtype=torch.float32))
        self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float32))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return (obs - self.offset) * self.scale


def relative_features() -> np.ndarray:
    """The fixed map (11 × 11) from the scaled observation to the tcp_offset actor's input: TCP height, g, φ,
    object − TCP, goal − TCP (xyz each) and goal − object (xy). Differences of scaled positions are scaled
    differences (the offsets cancel); no absolute x or y is left."""
    rows = [np.eye(11)[k] for k in (2, 3, 4)]
    for a, b, axes in ((5, 0, 3), (8, 0, 3), (8, 5, 2)):
        for i in range(axes):
            rows.append(np.eye(11)[a + i] - np.eye(11)[b + i])
    return np.array(rows)


def anchor_features(anchor: int) -> np.ndarray:
    """The fixed map (6 × 11) from the scaled observation to the phase_anchor actor's input: TCP height, g, φ
    and anchor − TCP (xyz), the anchor's position starting at observation index `anchor` (5 object, 8 goal)."""
    rows = [np.eye(11)[k] for k in (2, 3, 4)]
    rows += [np.eye(11)[anchor + i] - np.eye(11)[i] for i in range(3)]
    return np.array(rows)


class Actor(nn.Module):
    """μ_θ(s) ∈ [-1, 1]^act_dim, with one of ACTOR_HEADS (DDPGConfig.actor_head). `features` maps the scaled
    observation to the MLP's input; the anchor heads have a second map, `carry_features`, used where
    φ > CARRY_PROGRESS."""

    def __init__(self, scaler: ObsScaler, act_dim: int, hidden: tuple[int, ...], head: str = "absolute", max_offset: float = 0.5):
        super().__init__()
        self.scaler = scaler
        self.head, self.max_offset = head, max_offset
        anchored = [anchor_features(5), anchor_features(8)]
        maps = {"tcp_offset": [relative_features()], "phase_anchor": anchored, "anchor_offset": anchored}.get(head, [])
        for name, f in zip(("features", "carry_features"), maps):
            self.register_buffer(name, torch.as_tensor(f, dtype=torch.float32))
        self.net = mlp([len(maps[0]) if maps else len(scaler.offset), *hidden, act_dim], nn.Tanh)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.output(obs, self.net(self.inputs(obs)))

    def inputs(self, obs: torch.Tensor) -> torch.Tensor:
        """The MLP's input: the scaled observation, through the head's feature map."""
        x = self.scaler(obs)
        if self.head == "absolute":
            return x
        inputs = x @ self.features.T
        if self.head in ANCHOR_KINDS:
            inputs = torch.where(obs[..., 4:5] > CARRY_PROGRESS, x @ self.carry_features.T, inputs)
        return inputs

    def output(self, obs: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """The action from the MLP's output y ∈ [-1, 1]^act_dim: as it is (absolute), or the head's offset added to its base."""
        if self.head == "absolute":
            return y
        carry = obs[..., 4:5] > CARRY_PROGRESS
        base = torch.where(carry, obs[..., 8:11], obs[..., 5:8]) if self.head == "anchor_offset" else obs[..., :3]
        target = base + self.max_offset * y[..., :3]  # m
        normalized = (target - self.scaler.offset[:3]) * self.scaler.scale[:3]  # the workspace's [-1, 1] box
        clamped = normalized.clamp(-1.0, 1.0)
        if self.head == "anchor_offset":
            # straight-through: the part's centre lies below the box floor, so at the start most targets are
            # clamped, and a plain clamp passes them no gradient (the approach height was never learned)
            clamped = normalized + (clamped - normalized).detach()
        return torch.cat([clamped, y[..., 3:]], dim=-1)


class CriticEnsemble(nn.Module):
    """n critics Q_φ1..Q_φn(s, a) with the same layout, evaluated together: each layer is one batched
    matrix product over the stacked weights (n = 1 is the DDPG critic, n = 2 the clipped double-Q pair).
    Weights and biases are initialized as `nn.Linear` does. With `layer_norm`, every hidden layer is
    normalized (with a learned gain and bias per member) before its ReLU, as in RLPD's critics."""

    def __init__(self, scaler: ObsScaler, act_dim: int, hidden: tuple[int, ...], n: int, layer_norm: bool = False):
        super().__init__()
        self.scaler = scaler
        sizes = [len(scaler.offset) + act_dim, *hidden, 1]
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for fan_in, fan_out in zip(sizes[:-1], sizes[1:]):
            bound = 1.0 / fan_in**0.5
            self.weights.append(nn.Parameter(torch.empty(n, fan_in, fan_out).uniform_(-bound, bound)))
            self.biases.append(nn.Parameter(torch.empty(n, 1, fan_out).uniform_(-bound, bound)))
        self.norm_gains = nn.ParameterList([nn.Parameter(torch.ones(n, 1, h)) for h in hidden] if layer_norm else [])
        self.norm_biases = nn.ParameterList([nn.Parameter(torch.zeros(n, 1, h)) for h in hidden] if layer_norm else [])

    @property
    def n(self) -> int:
        return self.weights[0].shape[0]

    def forward(self, obs: torch.Tensor, act: torch.Tensor, members: slice | torch.Tensor = slice(None)) -> torch.Tensor:
        """Q values of the selected members (a slice or an index tensor), shape (members, batch)."""
        x = torch.cat([self.scaler(obs), act], dim=-1)
        params = [list(self.weights), list(self.biases), list(self.norm_gains), list(self.norm_biases)]
        if not (isinstance(members, slice) and members == slice(None)):  # no slicing: its backward would copy every weight gradient once more
            params = [[p[members] for p in group] for group in params]
        ws, bs, gains, shifts = params
        h = x.expand(ws[0].shape[0], *x.shape)
        for i, (w, b) in enumerate(zip(ws, bs)):
            h = torch.baddbmm(b, h, w)
            if i < len(ws) - 1:
                if gains:
                    h = nn.functional.layer_norm(h, h.shape[-1:]) * gains[i] + shifts[i]
                h = torch.relu(h)
        return h.squeeze(-1)


#: The behaviour-cloning term asks the gripper output for the expert's side of 0 by at least this much, no more:
#: pulling a tanh output towards a label of exactly ±1 saturates it, and a saturated gripper output never
#: learns again (ours; seen when early noisy release marks had taught "vacuum on" at the goal).
GRIP_MARGIN = 0.5


def bc_error(pi: torch.Tensor, act: torch.Tensor) -> torch.Tensor:
    """Per sample: the squared error of the target position plus a squared hinge on the gripper command."""
    grip = torch.relu(GRIP_MARGIN - torch.sign(act[..., 3]) * pi[..., 3]) ** 2
    return ((pi[..., :3] - act[..., :3]) ** 2).sum(-1) + grip


class DDPG:
    """Actor-critic with target networks; `update` takes one minibatch."""

    def __init__(self, obs_offset: np.ndarray, obs_scale: np.ndarray, act_dim: int, cfg: DDPGConfig, seed: int = 0):
        self.cfg = cfg
        self.act_dim = act_dim
        torch.manual_seed(seed)

        def scaler() -> ObsScaler:
            return ObsScaler(obs_offset, obs_scale)

        n_critics = 2 if cfg.clipped_double_q else 1
        self.actor = Actor(scaler(), act_dim, cfg.hidden, cfg.actor_head, cfg.max_offset)
        self.critic = CriticEnsemble(scaler(), act_dim, cfg.hidden, n_critics, cfg.critic_layer_norm)
        self.actor_target = Actor(scaler(), act_dim, cfg.hidden, cfg.actor_head, cfg.max_offset)
        self.critic_target = CriticEnsemble(scaler(), act_dim, cfg.hidden, n_critics, cfg.critic_layer_norm)
        self.actor_target.load_state_dict(self.actor.state_dict())
        self.critic_target.load_state_dict(self.critic.state_dict())
        # fused: one kernel per step for all parameters (same arithmetic as the loop version)
        self.actor_params = list(self.actor.parameters())
        self.actor_opt = torch.optim.Adam(self.actor_params, lr=cfg.lr_actor, fused=True)
        self.critic_opt = torch.optim.Adam(self.critic.parameters(), lr=cfg.lr_critic, fused=True)
        self.updates = 0  # critic steps so far (the actor steps on every policy_delay-th)
        self._soft_pairs = [
            (list(net.parameters()), list(tgt.parameters()))
            for net, tgt in ((self.actor, self.actor_target), (self.critic, self.critic_target))
        ]

    @property
    def policy_actor(self) -> Actor:
        """The actor that is evaluated and exported: the target actor with `act_with_target`, else the online one."""
        return self.actor_target if self.cfg.act_with_target else self.actor

    @torch.no_grad()
    def act(self, obs: np.ndarray, rng: np.random.Generator | None = None, sigma: float | None = None) -> np.ndarray:
        """Without `rng`, the evaluated policy's deterministic action (`policy_actor`); with it, the online
        actor's action plus Gaussian noise of std `sigma` (default: the initial exploration noise). Clipped to [-1, 1]."""
        actor = self.actor if rng is not None else self.policy_actor
        a = actor(torch.as_tensor(obs, dtype=torch.float32).unsqueeze(0)).squeeze(0).numpy()
        if rng is not None:
            a = a + rng.normal(0.0, self.cfg.exploration_noise if sigma is None else sigma, a.shape)
        return np.clip(a, -1.0, 1.0).astype(np.float32)

    def learn(self, replay: TaggedReplay, lam: float, batch_size: int, rng: np.random.Generator) -> tuple[dict[str, float], float]:
        """One environment step's learning: one update on a minibatch mixed by λ (Eq. 9); (statistics, expert share)."""
        batch = replay.sample(batch_size, lam, rng)
        return self.update(batch), batch.expert_ratio

    #: Keys of `update`'s statistics; the actor's three are present only when the actor stepped.
    CRITIC_STATS = ("critic_loss", "q_mean", "q_max")
    ACTOR_STATS = ("actor_loss", "actor_q", "bc_loss")

    def update(self, batch: Batch) -> dict[str, float]:
        """One critic step; every `policy_delay`-th call also an actor step and the soft target updates.

        Returns the update's statistics (gathered into floats with one conversion):
        - critic_loss: the critics' summed MSE to the TD target (the loss the critic step minimizes);
        - q_mean, q_max: mean and max over the batch of Q_φ1(s, a) for the stored actions, as evaluated
          for this step (before the critic step);
        - when the actor stepped: actor_loss = actor_q + bc_weight · bc_loss, where actor_q is the Q term
          (−mean Q_φ1(s, μ(s)), divided by the batch's mean |Q| when the BC term is on) and bc_loss the
          squared action error on the batch's expert (ζ = 1) samples; bc_loss is 0 when the batch holds
          none (always, without guidance) or bc_weight is 0.
        """
        obs = torch.as_tensor(batch.obs)
        act = torch.as_tensor(batch.act)
        rew = torch.as_tensor(batch.rew)
        next_obs = torch.as_tensor(batch.next_obs)
        target_q = self.td_target(rew, next_obs, torch.as_tensor(batch.done))
        q = self.critic(obs, act)
        critic_loss = nn.functional.mse_loss(q, target_q.expand_as(q)) * q.shape[0]  # sum of the members' losses
        self.critic_opt.zero_grad()
        critic_loss.backward()
        self.critic_opt.step()

        self.updates += 1
        names, actor_stats = self.CRITIC_STATS, []
        if self.updates % self.cfg.policy_delay == 0:
            names, actor_stats = names + self.ACTOR_STATS, self._actor_step(obs, act, batch.expert)
            with torch.no_grad():
                for params, targets in self._soft_pairs:
                    torch._foreach_lerp_(targets, params, self.cfg.tau)
        with torch.no_grad():  # the hot path: no autograd records, one tensor-to-Python conversion per update
            q1 = q[0]
            return dict(zip(names, torch.stack([critic_loss, q1.mean(), q1.max(), *actor_stats]).tolist()))

    @torch.no_grad()
    def td_target(self, rew: torch.Tensor, next_obs: torch.Tensor, done: torch.Tensor) -> torch.Tensor:
        """r + γ (1 − done) min_i Q'_i(s', μ'(s')): no bootstrap past a terminal state (done = terminated,
        not truncated), the minimum over the target critics (one critic: plain DDPG)."""
        next_act = self.actor_target(next_obs)
        if self.cfg.target_noise > 0:
            eps = (torch.randn_like(next_act) * self.cfg.target_noise).clamp(-self.cfg.target_noise_clip, self.cfg.target_noise_clip)
            next_act = (next_act + eps).clamp(-1.0, 1.0)
        next_q = self.critic_target(next_obs, next_act).min(0).values
        return rew + self.cfg.gamma * (1.0 - done) * next_q

    def _actor_step(self, obs: torch.Tensor, act: torch.Tensor, expert_mask: np.ndarray) -> list[torch.Tensor]:
        """Deterministic policy gradient on the first critic, plus behaviour cloning on expert samples.
        Returns the (actor loss, Q term, BC loss) tensors."""
        pi = self.actor(obs)
        q_pi = self.critic(obs, pi, slice(0, 1)).squeeze(0)  # the actor follows the first critic (as TD3)
        bc_loss = torch.zeros(())
        if self.cfg.bc_weight > 0 and expert_mask.any():
            expert = torch.as_tensor(expert_mask)
            sq_err = bc_error(pi[expert], act[expert])
            if self.cfg.q_filter:
                sq_err = sq_err * self._expert_beats_actor(obs[expert], act[expert], pi[expert])
            bc_loss = sq_err.mean()
            q_term = -q_pi.mean() / (q_pi.abs().mean().detach() + 1e-6)
            actor_loss = q_term + self.cfg.bc_weight * bc_loss
        else:
            actor_loss = q_term = -q_pi.mean()
        # gradients w.r.t. the actor only: the critic's weight gradients are never computed
        for p, g in zip(self.actor_params, torch.autograd.grad(actor_loss, self.actor_params)):
            p.grad = g
        self.actor_opt.step()
        return [actor_loss, q_term, bc_loss]

    @torch.no_grad()
    def _expert_beats_actor(self, obs: torch.Tensor, act: torch.Tensor, pi: torch.Tensor) -> torch.Tensor:
        """The Q-filter's mask, 1.0 where Q_φ1(s, a^e) > Q_φ1(s, μ(s)) and 0.0 elsewhere. A filtered sample
        still counts in the BC mean's denominator, so the term fades as the actor beats the demonstrations."""
        first = slice(0, 1)
        return (self.critic(obs, act, first) > self.critic(obs, pi, first)).squeeze(0).float()

    def state_dict(self) -> dict:
        return {
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "actor_target": self.actor_target.state_dict(),
            "critic_target": self.critic_target.state_dict(),
            "actor_opt": self.actor_opt.state_dict(),
            "critic_opt": self.critic_opt.state_dict(),
            "updates": self.updates,
        }

    def load_state_dict(self, state: dict) -> None:
        self.actor.load_state_dict(state["actor"])
        self.actor_target.load_state_dict(state["actor_target"])
        self.critic.load_state_dict(state["critic"])
        self.critic_target.load_state_dict(state["critic_target"])
        self.actor_opt.load_state_dict(state["actor_opt"])
        self.critic_opt.load_state_dict(state["critic_opt"])
        self.updates = state["updates"]
