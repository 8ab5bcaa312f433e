"""Where a training run's updates happen: beside the env loop in one thread (`LocalLearning`, the default), or in a
process of their own (`learner_process.LearnerProcess`, `train.learner_process = true`). The trainer drives either
through `Learning` and never asks which one it is: it hands over every stored transition with its tag ζ, says when
an environment step is done, takes the update statistics for each metrics row, and checkpoints what the learning
holds (the learner's networks and optimizers, both replay pools).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np

from mrguide.policies.guidance import GuidanceConfig, expert_ratio
from mrguide.policies.learners import Learner
from mrguide.policies.replay_buffer import TaggedReplay
from mrguide.policies.train_config import TrainConfig
from mrguide.policies.train_counters import TrainerCounters


def lam_at(step: int, train: TrainConfig, guidance: GuidanceConfig) -> float:
    """λ_t, the expert share of a minibatch at environment step `step` (Eq. 11); 0 without guidance."""
    if not guidance.enabled:
        return 0.0
    return expert_ratio(step, train.total_steps, guidance.lam_max, guidance.lam_min)


def evaluate_policy(env: Any, act: Callable[[np.ndarray], np.ndarray], seeds: Sequence[int]) -> tuple[float, float]:
    """(success rate, mean return) of the deterministic policy `act` in `env` (a `PickPlaceEnv`), one episode from each
    start state `seeds` gives."""
    successes, returns = 0, []
    for seed in seeds:
        obs, _ = env.reset(seed=seed)
        ret = 0.0
        while True:
            obs, r, term, trunc, info = env.step(act(obs))
            ret += r
            if term or trunc:
                break
        successes += int(info["is_success"])
        returns.append(ret)
    return successes / len(seeds), float(np.mean(returns))


class UpdateStats:
    """Update statistics and expert shares summed since the last metrics row (`take` gives their means)."""

    def __init__(self) -> None:
        self.clear()

    def clear(self) -> None:
        self.sums: dict[str, float] = {}
        self.counts: dict[str, int] = {}
        self.ratio_sum, self.ratio_n = 0.0, 0

    def add(self, stats: dict[str, float], ratio: float) -> None:
        """One `learn` call's statistics and its minibatch's expert share."""
        self.ratio_sum += ratio
        self.ratio_n += 1
        for k, v in stats.items():
            self.sums[k] = self.sums.get(k, 0.0) + v
            self.counts[k] = self.counts.get(k, 0) + 1

    def merge(self, other: UpdateStats) -> None:
        """Add the sums of `other` (the statistics a learner process published) to these."""
        self.ratio_sum += other.ratio_sum
        self.ratio_n += other.ratio_n
        for k, v in other.sums.items():
            self.sums[k] = self.sums.get(k, 0.0) + v
            self.counts[k] = self.counts.get(k, 0) + other.counts[k]

    def take(self, last_ratio: float) -> tuple[float, dict[str, float]]:
        """(mean expert share, or `last_ratio` with no update; the statistics' means), and start again from zero."""
        ratio = self.ratio_sum / self.ratio_n if self.ratio_n else last_ratio
        means = {k: float(f"{self.sums[k] / n:.6g}") for k, n in self.counts.items()}
        self.clear()
        return ratio, means


class Learning(Protocol):
    """What the trainer asks of where its updates happen."""

    #: The update statistics since the last metrics row.
    stats: UpdateStats

    def add(self, obs: np.ndarray, act: np.ndarray, rew: float, next_obs: np.ndarray, done: bool, zeta: int) -> None:
        """Store τ = (s, a, r, s', done, ζ) (Eq. 7)."""
        ...

    def stepped(self, step: int) -> None:
        """Environment step `step` is done (counted after the step): learn, or let the learner know."""
        ...

    def episode_end(self, step: int) -> None:
        """An agent episode (and its demonstration) ended at `step`: a point to stop at if the learning cannot go on
        (raises then)."""
        ...

    def forget(self) -> None:
        """Empty both pools, after every transition stored so far: a person corrected what they had taught, and the
        demonstrations made before aimed elsewhere, every reward was the old grasp's."""
        ...

    def state(self) -> dict:
        """The checkpoint's `agent`, `agent_pool` and `expert_pool` (and what else resumes this learning)."""
        ...

    def load(self, state: dict) -> None:
        """Restore what `state` gave, from a checkpoint (errors: it does not fit)."""
        ...

    def close(self) -> None: ...


class LocalLearning:
    """The learner's updates in the trainer's thread: one `learn` call after every environment step once the buffer
    holds `learning_starts` transitions, on minibatches drawn with the trainer's RNG."""

    def __init__(
        self,
        agent: Learner,
        cfg: TrainConfig,
        lam: Callable[[], float],
        rng: np.random.Generator,
        counters: TrainerCounters,
        obs_dim: int,
        act_dim: int,
    ):
        self.agent, self.cfg, self.lam, self.rng, self.counters = agent, cfg, lam, rng, counters
        self.replay = TaggedReplay(cfg.buffer_size, obs_dim, act_dim)
        self.stats = UpdateStats()

    def add(self, obs: np.ndarray, act: np.ndarray, rew: float, next_obs: np.ndarray, done: bool, zeta: int) -> None:
        self.replay.add(obs, act, rew, next_obs, done, zeta)

    def stepped(self, step: int) -> None:
        if len(self.replay) >= self.cfg.learning_starts:
            t = time.perf_counter()
            stats, ratio = self.agent.learn(self.replay, self.lam(), self.cfg.batch_size, self.rng)
            self.counters.update_s += time.perf_counter() - t
            self.counters.last_ratio = ratio
            self.stats.add(stats, ratio)

    def episode_end(self, step: int) -> None:
        """Nothing to check: the updates ran in this thread."""

    def forget(self) -> None:
        self.replay.clear()

    def state(self) -> dict:
        return {
            "agent": self.agent.state_dict(),
            "agent_pool": self.replay.agent.state(),
            "expert_pool": self.replay.expert.state(),
        }

    def load(self, state: dict) -> None:
        self.agent.load_state_dict(state["agent"])
        self.replay.agent.load(state["agent_pool"])
        self.replay.expert.load(state["expert_pool"])

    def close(self) -> None:
        """Nothing to end."""
