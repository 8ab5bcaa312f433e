"""Learning-curves aggregation: the convergence criterion and the table built from run directories."""

import csv

from mrguide.policies.experiments import convergence_step, summarize
from mrguide.policies.train import METRIC_FIELDS


def evals(rates):
    return [{"step": str(1000 * (i + 1)), "success_rate": str(r), "mean_return": "0"} for i, r in enumerate(rates)]


def test_convergence_needs_the_window_to_reach_and_keep_the_threshold():
    # window of 20 episodes = the last 2 evaluations of 10
    assert convergence_step(evals([0.0, 0.9, 0.8, 1.0, 0.9]), 10) == 3000  # (0.9 + 0.8) / 2 = 0.85
    assert convergence_step(evals([0.0, 1.0, 0.6, 1.0, 1.0]), 10) == 3000  # exactly 0.8 counts
    assert convergence_step(evals([0.0, 1.0, 0.5, 1.0, 1.0]), 10) == 5000  # one 0.5 keeps two windows at 0.75
    assert convergence_step(evals([1.0, 1.0, 1.0, 0.2, 1.0]), 10) is None  # collapses at the end
    assert convergence_step(evals([0.5] * 5), 10) is None
    assert convergence_step(evals([0.0, 0.8]), 20) == 2000  # one evaluation fills the window


def write_run(run, eval_rates, asked_per_row, wall=100.0):
    run.mkdir(parents=True)
    with (run / "eval.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, ["step", "success_rate", "mean_return"])
        w.writeheader()
        w.writerows(evals(eval_rates))
    with (run / "metrics.csv").open("w", newline="") as fh:
        w = csv.DictWriter(fh, METRIC_FIELDS, restval="0")
        w.writeheader()
        for i, asked in enumerate(asked_per_row):
            w.writerow({"step": 500 * (i + 1), "asked": asked, "expert_ratio": 0.5})
    (run / "done").write_text(f"{wall}\n5.0\n")


def test_summary_table_from_run_directories(tmp_path):
    steps = 4000
    for s in range(2):
        write_run(tmp_path / "baseline" / f"seed{s}", [0.0] * 4, [0] * 8)
    # seed 0 converges at 2000 having asked 30 annotations by then; seed 1 never does
    write_run(tmp_path / "guided" / "seed0", [0.5, 0.9, 1.0, 1.0], [10, 20, 25, 30, 40, 40, 40, 40])
    write_run(tmp_path / "guided" / "seed1", [0.5, 0.9, 1.0, 0.3], [10, 20, 30, 50, 60, 60, 60, 60], wall=300.0)
    md = summarize(tmp_path, 2, steps, eval_episodes=10)
    with (tmp_path / "runs.csv").open() as fh:
        runs = {(r["variant"], r["seed"]): r for r in csv.DictReader(fh)}
    assert runs["guided", "0"]["convergence_step"] == "3000"  # (0.9 + 1.0) / 2 at 3000; (0.5 + 0.9) / 2 at 2000 is 0.7
    assert runs["guided", "0"]["annotations_until_convergence"] == "40"
    assert runs["guided", "1"]["convergence_step"] == ""
    assert runs["guided", "1"]["annotations_total"] == "60"
    with (tmp_path / "summary.csv").open() as fh:
        table = {r["variant"]: r for r in csv.DictReader(fh)}
    assert table["guided"]["converged_by_end"] == "1" and table["baseline"]["converged_by_end"] == "0"
    assert float(table["guided"]["final_eval_success"]) == 0.65
    assert float(table["guided"]["wall_s_per_run_median"]) == 200.0
    for fig in ("fig3_learning_curves.png", "fig5_convergence.png", "fig9_expert_effort.png"):
        assert (tmp_path / fig).stat().st_size > 1000
    assert "| guided | 1/2 | 1/2 | 3000 |" in md.read_text()
