"""Fig. 6: distances to the training region, the goal grid, the bins, and a tiny run on Ray."""

import csv

import numpy as np
import pytest

from mrguide.cli import main
from mrguide.experiments.generalization import GeneralizationConfig, bins, goal_targets, region_distance, runs


def test_region_distance():
    lo, hi = (0.4, 0.12), (0.6, 0.3)
    assert region_distance(np.array([0.5, 0.2]), lo, hi) == 0.0
    assert region_distance(np.array([0.5, 0.4]), lo, hi) == pytest.approx(0.1)
    assert region_distance(np.array([0.3, 0.0]), lo, hi) == pytest.approx(np.hypot(0.1, 0.12))


def test_goal_grid_reaches_the_requested_distance_inside_the_box():
    cfg = GeneralizationConfig()
    targets = goal_targets(cfg, runs(cfg, None)[0])
    d = np.array([t[2] for t in targets])
    assert d.max() > 0.18 and d.max() <= 0.21 + 1e-9 and (d == 0).sum() > 10
    xy = np.array([t[:2] for t in targets])
    assert np.all(xy >= np.array(cfg.workspace_low[:2]) - 1e-9) and np.all(
        xy <= np.array(cfg.workspace_high[:2]) + 1e-9
    )


def test_bins_pool_seeds_and_give_wilson_intervals():
    cfg = GeneralizationConfig(max_distance=0.09, bin_width=0.03)
    rows = [
        {"x": "0.5", "y": "0.2", "distance_m": "0.0", "episodes": "20", "successes": "19"},
        {"x": "0.5", "y": "0.2", "distance_m": "0.0", "episodes": "20", "successes": "20"},  # another seed, same target
        {"x": "0.5", "y": "0.35", "distance_m": "0.05", "episodes": "20", "successes": "10"},
        {"x": "0.5", "y": "0.39", "distance_m": "0.09", "episodes": "20", "successes": "0"},
    ]  # the last edge is in
    table = bins(cfg, rows)
    assert [(t["targets"], t["episodes"], t["success"]) for t in table] == [(1, 40, 0.975), (1, 20, 0.5), (1, 20, 0.0)]
    assert table[0]["ci_low"] < 0.975 < table[0]["ci_high"] and table[2]["ci_low"] == 0.0


def test_tiny_generalization_on_local_ray(tiny_experiment, capsys):
    write, out = tiny_experiment
    cfg = write("gen", "seeds = 1\nsteps = 200\ngrid_step = 0.1\nmax_distance = 0.09\nbin_width = 0.03\nepisodes = 1\n")
    assert (
        main(["experiment", "generalization", "--config", str(cfg), "--out", str(out), "--workers", "2", "--quiet"])
        == 0
    )
    with (out / "guided" / "seed0" / "goals.csv").open() as fh:
        goals = list(csv.DictReader(fh))
    assert goals and all(r["episodes"] == "1" and r["successes"] in ("0", "1") for r in goals)
    summary = (out / "summary.csv").read_text().splitlines()
    assert summary[0] == "bin_low_m,bin_high_m,targets,episodes,success,ci_low,ci_high" and len(summary) == 4
    assert (out / "fig6_generalization.png").stat().st_size > 10_000
