"""Wilson and bootstrap intervals; the convergence rule with 'reached at the end'."""

import numpy as np
import pytest

from mrguide.experiments.stats import Convergence, bootstrap, convergence, wilson


def test_wilson_interval_known_values():
    lo, hi = wilson(9, 10)
    assert (round(lo, 3), round(hi, 3)) == (0.596, 0.982)  # textbook value for 9/10
    assert wilson(0, 10)[0] == 0.0 and wilson(10, 10)[1] == pytest.approx(1.0)
    assert wilson(0, 0) == (0.0, 1.0)
    lo, hi = wilson(50, 100)
    assert lo == pytest.approx(1 - hi) and lo < 0.5 < hi


def test_bootstrap_is_seeded_and_brackets_the_mean():
    x = np.random.default_rng(1).normal(5.0, 1.0, 200)
    a, b = bootstrap(x), bootstrap(x)
    assert a == b and a[0] < x.mean() < a[1] and a[1] - a[0] < 0.4
    assert np.isnan(bootstrap([])[0])


def rates_at(*rates):
    return [1000 * (i + 1) for i in range(len(rates))], list(rates)


def test_convergence_rule():
    assert convergence(*rates_at(0.0, 0.9, 0.8, 1.0, 0.9), 10) == Convergence(3000, False)
    assert convergence(*rates_at(0.0, 1.0, 0.6, 1.0, 1.0), 10) == Convergence(3000, False)  # exactly 0.8 counts
    assert convergence(*rates_at(0.0, 1.0, 0.5, 1.0, 1.0), 10) == Convergence(None, True)  # first ≥ 0.8 at the end
    assert convergence(*rates_at(0.0, 1.0, 0.5, 1.0, 1.0, 0.9), 10) == Convergence(5000, False)  # ... and it stayed
    assert convergence(*rates_at(1.0, 1.0, 1.0, 0.2, 1.0), 10) == Convergence(None, False)  # collapsed
    assert convergence(*rates_at(0.0, 0.0, 0.0, 0.7, 1.0), 10) == Convergence(None, True)  # only the last window
    assert convergence(*rates_at(0.0, 0.8), 20) == Convergence(None, True)  # one evaluation fills the window
    assert convergence(*rates_at(0.8, 0.8), 20) == Convergence(1000, False)
