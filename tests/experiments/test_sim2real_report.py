"""The sim-to-real report's table (experiments/sim2real_report.py): per condition the pooled rate and, over the
seeds (each a calibration draw of the played cell), the least and the median seed's rate."""

from __future__ import annotations

from mrguide.experiments.sim2real import ConditionResult
from mrguide.experiments.sim2real_report import report_files


def test_the_table_reports_the_least_and_the_median_seed():
    outcomes = {0: ["success", "success"], 1: ["success", "dropped"], 2: ["no_grasp", "dropped"]}
    result = ConditionResult("mujoco_hmd", outcomes)
    summary = result.summary()
    assert (summary["seed_min"], summary["seed_median"]) == (0.0, 0.5)
    table = report_files([result], "").get("sim2real.md", b"").decode()
    row = next(line for line in table.splitlines() if line.startswith("| mujoco_hmd"))
    assert "| 50 % |" in row and "| 0 / 50 % |" in row and row.count("|") == table.splitlines()[0].count("|")


def test_episodes_the_cells_lag_voided_are_counted_apart_and_not_judged():
    """An episode in which the simulated cell ran behind the wall clock is not the policy's: out of every rate."""
    outcomes = {0: ["success", "cell_behind"], 1: ["success", "no_grasp"], 2: ["cell_behind", "cell_behind"]}
    summary = ConditionResult("mujoco_hmd", outcomes).summary()
    assert summary["episodes"] == 3 and summary["success_rate"] == 2 / 3 and summary["cell_behind"] == 3
    assert (summary["seed_min"], summary["seed_median"]) == (0.5, 0.75)  # the all-voided draw has no rate
    table = report_files([ConditionResult("mujoco_hmd", outcomes)], "").get("sim2real.md", b"").decode()
    row = next(line for line in table.splitlines() if line.startswith("| mujoco_hmd"))
    assert "| 3, 3 | 67 % |" in row and row.rstrip(" |").endswith("3")
