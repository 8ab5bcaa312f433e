"""Running episodes in the twin with any action source, and summarizing their outcomes."""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from mrguide.twin.env import PickPlaceEnv


@dataclass
class EpisodeResult:
    seed: int
    outcome: str
    ret: float
    steps: int


@dataclass
class RolloutSummary:
    """Outcomes of a batch of episodes and how long they took."""

    episodes: list[EpisodeResult] = field(default_factory=list)
    wall_s: float = 0.0

    @property
    def success_rate(self) -> float:
        return float(np.mean([e.outcome == "success" for e in self.episodes])) if self.episodes else 0.0

    @property
    def decisions(self) -> int:
        return sum(e.steps for e in self.episodes)

    def outcomes(self) -> Counter:
        return Counter(e.outcome for e in self.episodes)


def run_episode(
    env: PickPlaceEnv, policy: Callable[[np.ndarray], np.ndarray], seed: int, options: dict | None = None
) -> EpisodeResult:
    """One episode from `env.reset(seed)` with actions from `policy(obs)`."""
    obs, _ = env.reset(seed=seed, options=options)
    ret, steps = 0.0, 0
    while True:
        obs, r, term, trunc, info = env.step(policy(obs))
        ret += r
        steps += 1
        if term or trunc:
            return EpisodeResult(seed, info["outcome"], ret, steps)


def run_episodes(
    env: PickPlaceEnv,
    policy: Callable[[np.ndarray], np.ndarray],
    seeds: Iterable[int],
    progress: Callable | None = None,
) -> RolloutSummary:
    """Episodes for each seed; `progress(result)` is called after each one."""
    summary = RolloutSummary()
    t0 = time.perf_counter()
    for seed in seeds:
        res = run_episode(env, policy, seed)
        summary.episodes.append(res)
        if progress:
            progress(res)
    summary.wall_s = time.perf_counter() - t0
    return summary
