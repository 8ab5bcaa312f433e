"""Expert-tagged replay (paper Eq. 7-9): an agent pool (ζ = 0) and an expert pool (ζ = 1).

Each pool is a numpy ring buffer of (s, a, r, s', done). A minibatch draws its expert share from a
binomial with probability λ_t (Eq. 9), capped by what the expert pool holds; the realized ratio is
returned with every batch so it can be recorded (Fig. 9).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class RingBuffer:
    """Fixed-capacity FIFO of transitions, float32 storage (1e6 x 11-dim obs ≈ 110 MB for s and s')."""

    FIELDS = ("obs", "act", "rew", "next_obs", "done")

    def __init__(self, capacity: int, obs_dim: int, act_dim: int):
        if capacity < 1:
            raise ValueError(f"buffer capacity must be >= 1, got {capacity}")
        self.capacity = capacity
        self.obs = np.zeros((capacity, obs_dim), np.float32)
        self.act = np.zeros((capacity, act_dim), np.float32)
        self.rew = np.zeros(capacity, np.float32)
        self.next_obs = np.zeros((capacity, obs_dim), np.float32)
        self.done = np.zeros(capacity, np.float32)
        self.pos = 0
        self.size = 0

    def add(self, obs, act, rew: float, next_obs, done: bool) -> None:
        i = self.pos
        self.obs[i], self.act[i], self.rew[i], self.next_obs[i], self.done[i] = obs, act, rew, next_obs, float(done)
        self.pos = (i + 1) % self.capacity
        self.size = min(self.size + 1, self.capacity)

    def clear(self) -> None:
        """Forget every transition (the storage stays allocated)."""
        self.pos = self.size = 0

    def index(self, idx: np.ndarray) -> tuple[np.ndarray, ...]:
        return tuple(getattr(self, f)[idx] for f in self.FIELDS)

    def state(self) -> dict[str, np.ndarray]:
        """The filled part in insertion order (oldest first), for checkpoints."""
        order = (
            np.arange(self.size) if self.size < self.capacity else (np.arange(self.capacity) + self.pos) % self.capacity
        )
        return {f: getattr(self, f)[order] for f in self.FIELDS}

    def load(self, state: dict[str, np.ndarray]) -> None:
        n = len(state["rew"])
        if n > self.capacity:
            raise ValueError(f"checkpoint holds {n} transitions, more than the capacity {self.capacity}")
        for f in self.FIELDS:
            arr = getattr(self, f)
            if state[f].shape[1:] != arr.shape[1:]:
                raise ValueError(
                    f"checkpoint field {f} has shape {state[f].shape}, buffer expects (*, {arr.shape[1:]})"
                )
            arr[:n] = state[f]
        self.size, self.pos = n, n % self.capacity


@dataclass
class Batch:
    obs: np.ndarray
    act: np.ndarray
    rew: np.ndarray
    next_obs: np.ndarray
    done: np.ndarray
    expert: np.ndarray  # bool mask, ζ of each sample
    expert_ratio: float


class TaggedReplay:
    """Agent and expert pools sampled as a λ-mixture."""

    def __init__(self, capacity: int, obs_dim: int, act_dim: int):
        self.pools = {0: RingBuffer(capacity, obs_dim, act_dim), 1: RingBuffer(capacity, obs_dim, act_dim)}

    def add(self, obs, act, rew: float, next_obs, done: bool, zeta: int) -> None:
        """Store τ = (s, a, r, s', done, ζ) (Eq. 7)."""
        self.pools[int(zeta)].add(obs, act, rew, next_obs, done)

    @property
    def agent(self) -> RingBuffer:
        return self.pools[0]

    @property
    def expert(self) -> RingBuffer:
        return self.pools[1]

    def __len__(self) -> int:
        return self.agent.size + self.expert.size

    def clear(self) -> None:
        """Forget every transition of both pools."""
        self.agent.clear()
        self.expert.clear()

    def sample(self, batch_size: int, lam: float, rng: np.random.Generator) -> Batch:
        """A minibatch with each sample expert-drawn with probability λ (Eq. 9), capped by the pools' sizes."""
        if len(self) == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        n_exp = min(int(rng.binomial(batch_size, float(np.clip(lam, 0.0, 1.0)))), self.expert.size)
        if self.agent.size == 0:  # only expert data so far
            n_exp = batch_size
        return self._batch(batch_size, n_exp, rng)

    def sample_split(self, batch_size: int, n_expert: int, rng: np.random.Generator) -> Batch:
        """A minibatch of exactly `n_expert` expert samples (RLPD's symmetric sampling), all agent data while the
        expert pool is empty, all expert data while the agent pool is."""
        if len(self) == 0:
            raise ValueError("cannot sample from an empty replay buffer")
        n_exp = batch_size if self.agent.size == 0 else (n_expert if self.expert.size else 0)
        return self._batch(batch_size, n_exp, rng)

    def _batch(self, batch_size: int, n_exp: int, rng: np.random.Generator) -> Batch:
        n_agent = batch_size - n_exp
        parts = []
        if n_exp:
            parts.append(self.expert.index(rng.integers(0, self.expert.size, n_exp)))
        if n_agent:
            parts.append(self.agent.index(rng.integers(0, self.agent.size, n_agent)))
        obs, act, rew, next_obs, done = (np.concatenate([p[k] for p in parts]) for k in range(5))
        return Batch(
            obs, act, rew, next_obs, done, expert=np.arange(batch_size) < n_exp, expert_ratio=n_exp / batch_size
        )
