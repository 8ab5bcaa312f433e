"""Statistics shared by the experiments: binomial (Wilson) and bootstrap intervals, the convergence rule."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

#: Convergence threshold on the evaluation success over the last WINDOW_EPISODES episodes (ours: the paper
#: says "stays above the task threshold" without a number).
CONVERGENCE_THRESHOLD = 0.8
WINDOW_EPISODES = 20
#: A person's time per mark, s: person-minutes = marks × this / 60 (our assumption: a few seconds per mark).
PERSON_SECONDS_PER_MARK = 4.0


def person_minutes(marks: float | None) -> float | None:
    """A person's time for `marks` marks, min (one decimal), at PERSON_SECONDS_PER_MARK each."""
    return None if marks is None else round(marks * PERSON_SECONDS_PER_MARK / 60.0, 1)


def wilson(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """95 % Wilson score interval of a binomial proportion (n = 0 gives (0, 1))."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def bootstrap(
    values: Sequence[float], statistic: Callable[[np.ndarray], float] = np.mean, resamples: int = 10_000, seed: int = 0
) -> tuple[float, float]:
    """95 % percentile-bootstrap interval of `statistic` over `values` (seeded: the same data, the same interval)."""
    x = np.asarray(values, dtype=float)
    if x.size == 0:
        return math.nan, math.nan
    rng = np.random.default_rng(seed)
    stats = np.array([statistic(x[rng.integers(0, x.size, x.size)]) for _ in range(resamples)])
    return float(np.percentile(stats, 2.5)), float(np.percentile(stats, 97.5))


@dataclass(frozen=True)
class Convergence:
    """When a run converged: `step` of the evaluation from which the window stays ≥ threshold, or None.

    `at_end` is True when the window first reached the threshold only at the final evaluation: that is
    reported, but not counted as convergence (nothing shows it would have stayed).
    """

    step: int | None
    at_end: bool


def convergence(
    steps: Sequence[int],
    rates: Sequence[float],
    episodes_per_eval: int,
    threshold: float = CONVERGENCE_THRESHOLD,
    window: int = WINDOW_EPISODES,
) -> Convergence:
    """The convergence rule over a run's evaluations (success rates at training steps)."""
    k = max(1, -(-window // episodes_per_eval))  # evaluations per window
    moving = [float(np.mean(rates[i - k + 1 : i + 1])) for i in range(k - 1, len(rates))]
    for i in range(len(moving)):
        if min(moving[i:]) >= threshold:
            if i == len(moving) - 1:
                return Convergence(None, True)
            return Convergence(int(steps[i + k - 1]), False)
    return Convergence(None, False)
