"""A policy a person taught to grip a part off its centre runs on the cell: the dry run of the part's config."""

from __future__ import annotations

from pathlib import Path

from mrguide.deploy.runlog import read_log

ROOT = Path(__file__).parents[2]
#: A committed taught policy of the parts experiment (docs/results/parts: seed 6 of the hole plate, judged 100 %).
POLICY = ROOT / "docs/results/parts/hole_plate/taught/seed6/policy.npz"


def test_a_taught_hole_plate_policy_places_the_plate_in_a_dry_run(run_cli, tmp_path):
    """The plate's cup can seal only on its frame, 3.5-5 cm off the centre (over the hole it cannot): a plate placed
    is a plate gripped where the person taught, through the whole stack (runtime, IK, CANopen, the twin's plate)."""
    log = tmp_path / "plate.jsonl"
    config = ROOT / "configs/parts/hole_plate.toml"
    argv = ["deploy", "--dry-run", "--config", config, "--policy", POLICY, "--episodes", 3, "--seed", 0, "--log", log]
    res = run_cli([*argv, "--quiet"])
    assert res.code == 0, res.err
    records = list(read_log(log))
    assert records[0]["config"] == str(config)
    outcomes = [r["outcome"] for r in records if r["kind"] == "episode_end"]
    assert len(outcomes) == 3 and outcomes.count("success") >= 2, outcomes  # runs.csv: 50 of 50 placed in the twin
