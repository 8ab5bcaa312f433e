"""The networks both learners use: the anchored actor and a batched critic ensemble, with fixed input scaling.

The actor outputs the TCP target as an offset from the phase's anchor — the part up to the lift, the goal
from transport on — and sees only what that phase depends on: the TCP height, g, φ and the anchor relative
to the TCP. Each phase is then equivariant to moving its own anchor and blind to the other (a far goal
cannot disturb the grasp; Fig. 6), and where the arm strays off the demonstrated path the target stays on
the anchor unless the MLP moves it (Fig. 7). The exported policy file declares this head (`anchor_offset`)
and `mrguide.deploy.policy` applies it with numpy.
"""

from __future__ import annotations

import itertools

import numpy as np
import torch
from torch import nn

from mrguide.robot import Workspace
from mrguide.task import OBS_DIM, OBS_GOAL, OBS_GRIP, OBS_OBJECT, OBS_PROGRESS, OBS_TCP

#: φ above which the actor anchors on the goal instead of the part: transport and release (φ = 3/5, 4/5, 1).
CARRY_PROGRESS = 0.5
#: m: the largest offset per axis the actor adds to its anchor (ours).
MAX_OFFSET = 0.5


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

    offset: torch.Tensor  # buffers (registered in __init__)
    scale: torch.Tensor

    def __init__(self, offset: np.ndarray, scale: np.ndarray):
        super().__init__()
        self.register_buffer("offset", torch.as_tensor(offset, dtype=torch.float32))
        self.register_buffer("scale", torch.as_tensor(scale, dtype=torch.float32))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return (obs - self.offset) * self.scale


def anchor_features(anchor: slice) -> np.ndarray:
    """The fixed map (6 × 11) from the scaled observation to the actor's input: TCP height, g, φ and anchor − TCP
    (xyz), the anchor being the observation's `anchor` slice (OBS_OBJECT or OBS_GOAL)."""
    eye = np.eye(OBS_DIM)
    rows = [eye[k] for k in (OBS_TCP.start + 2, OBS_GRIP, OBS_PROGRESS)]  # TCP z, g, φ
    rows += [eye[anchor.start + i] - eye[OBS_TCP.start + i] for i in range(3)]
    return np.array(rows)


class Actor(nn.Module):
    """μ_θ(s) ∈ [-1, 1]^act_dim: the target = anchor + MAX_OFFSET · y[:3] (normalized to the workspace box), the
    gripper command y[3], with y = tanh(MLP(features)); `features` and `carry_features` map the scaled
    observation to the MLP's input before and after φ = CARRY_PROGRESS."""

    features: torch.Tensor  # buffers (registered in __init__)
    carry_features: torch.Tensor

    def __init__(self, scaler: ObsScaler, act_dim: int, hidden: tuple[int, ...]):
        super().__init__()
        self.scaler = scaler
        self.register_buffer("features", torch.as_tensor(anchor_features(OBS_OBJECT), dtype=torch.float32))
        self.register_buffer("carry_features", torch.as_tensor(anchor_features(OBS_GOAL), dtype=torch.float32))
        self.net = mlp([len(self.features), *hidden, act_dim], nn.Tanh)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.output(obs, self.net(self.inputs(obs)))

    def inputs(self, obs: torch.Tensor) -> torch.Tensor:
        """The MLP's input: the scaled observation through the phase's feature map."""
        x = self.scaler(obs)
        inputs = x @ self.features.T
        return torch.where(
            obs[..., OBS_PROGRESS : OBS_PROGRESS + 1] > CARRY_PROGRESS, x @ self.carry_features.T, inputs
        )

    def output(self, obs: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
        """The action for the MLP's output y ∈ [-1, 1]^act_dim: the offset added to the phase's anchor."""
        carry = obs[..., OBS_PROGRESS : OBS_PROGRESS + 1] > CARRY_PROGRESS
        base = torch.where(carry, obs[..., OBS_GOAL], obs[..., OBS_OBJECT])
        target = base + MAX_OFFSET * y[..., :3]  # m
        normalized = (target - self.scaler.offset[:3]) * self.scaler.scale[:3]  # the workspace's [-1, 1] box
        # straight-through clamp: the part's centre lies below the box floor, so at the start most targets are
        # clamped, and a plain clamp passes them no gradient (the approach height was never learned)
        clamped = normalized + (normalized.clamp(-1.0, 1.0) - normalized).detach()
        return torch.cat([clamped, y[..., 3:]], dim=-1)


class CriticEnsemble(nn.Module):
    """n critics Q_φ1..Q_φn(s, a) with the same layout, evaluated together: each layer is one batched
    matrix product over the stacked weights (DDPG's clipped double-Q pair, SAC's ensemble). Weights and
    biases are initialized as `nn.Linear` does. Every hidden layer is normalized (LayerNorm, with a learned
    gain and bias per member) before its ReLU, as in RLPD's critics: without it, the guided critic's loss grew
    without bound once the expert intake closed under noisy marks and the policy collapsed (docs: the learner)."""

    def __init__(self, scaler: ObsScaler, act_dim: int, hidden: tuple[int, ...], n: int):
        super().__init__()
        self.scaler = scaler
        sizes = [len(scaler.offset) + act_dim, *hidden, 1]
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for fan_in, fan_out in itertools.pairwise(sizes):
            bound = 1.0 / fan_in**0.5
            self.weights.append(nn.Parameter(torch.empty(n, fan_in, fan_out).uniform_(-bound, bound)))
            self.biases.append(nn.Parameter(torch.empty(n, 1, fan_out).uniform_(-bound, bound)))
        self.norm_gains = nn.ParameterList([nn.Parameter(torch.ones(n, 1, h)) for h in hidden])
        self.norm_biases = nn.ParameterList([nn.Parameter(torch.zeros(n, 1, h)) for h in hidden])

    def forward(
        self, obs: torch.Tensor, act: torch.Tensor, members: slice | torch.Tensor = slice(None)
    ) -> torch.Tensor:
        """Q values of the selected members (a slice or an index tensor), shape (members, batch)."""
        x = torch.cat([self.scaler(obs), act], dim=-1)
        params = [list(self.weights), list(self.biases), list(self.norm_gains), list(self.norm_biases)]
        if not (
            isinstance(members, slice) and members == slice(None)
        ):  # no slicing: its backward would copy every weight gradient once more
            params = [[p[members] for p in group] for group in params]
        ws, bs, gains, shifts = params
        h = x.expand(ws[0].shape[0], *x.shape)
        for i, (w, b) in enumerate(zip(ws, bs)):
            h = torch.baddbmm(b, h, w)
            if i < len(ws) - 1:
                h = torch.relu(nn.functional.layer_norm(h, h.shape[-1:]) * gains[i] + shifts[i])
        return h.squeeze(-1)
