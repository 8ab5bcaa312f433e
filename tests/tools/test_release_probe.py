"""The release probe: where a policy opens the vacuum over the goal."""

import csv
import math
from pathlib import Path

from tests.tools.conftest import load_tool

release_probe = load_tool("release_probe")

MAIN5K = Path(__file__).parents[2] / "docs/results/sim2real-main5k/policy.npz"


def test_a_policy_that_places_opens_near_the_goal_and_the_csv_says_so(tmp_path, capsys):
    assert release_probe.main([str(MAIN5K), "--episodes", "2", "--out", str(tmp_path)]) == 0
    with open(tmp_path / "release_probe.csv") as f:
        (row,) = list(csv.DictReader(f))
    assert row["policy"] == str(MAIN5K) and row["episodes"] == "2"
    assert int(row["released"]) == 2 and int(row["success"]) == 2
    assert float(row["tcp_goal_median_m"]) < 0.02  # within ε, as every success must be
    assert "success 2" in capsys.readouterr().out


def test_a_policy_that_never_grasps_releases_nothing(policy_file, tmp_path):
    """Zero weights: the target on the anchor (the part's centre) and the gripper output at 0 (vacuum never on)."""
    from mrguide.deploy.policy import ExportedPolicy
    from mrguide.twin.env import PickPlaceEnv

    env = PickPlaceEnv()
    try:
        row = release_probe.probe(env, ExportedPolicy.load(policy_file(tmp_path / "p.npz")), 1)
    finally:
        env.close()
    assert row["success"] == 0 and row["released"] == 0
    assert row["never_approached"] == 1  # its target, the part's centre, lies 10.5 cm below the pre-grasp point
    assert math.isnan(float(row["tcp_goal_median_m"])) and math.isnan(float(row["grasp_offset_m"]))
