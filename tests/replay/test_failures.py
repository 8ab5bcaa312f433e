"""`python -m mrguide.replay.failures`: the failed episodes of run logs, recomputed from the committed slim logs of
the 200-episode lift-drop runs exactly as the results page quotes them (`lift-drops-200/failures.txt`)."""

from __future__ import annotations

from pathlib import Path

from mrguide.replay.failures import main

RUNS = Path(__file__).parents[2] / "docs" / "results" / "lift-drops-200"


def test_the_committed_failures_are_what_the_logs_say(capsys, monkeypatch):
    monkeypatch.chdir(RUNS.parents[2])
    logs = ["docs/results/lift-drops-200/mujoco_cell.jsonl.gz", "docs/results/lift-drops-200/real_cell.jsonl.gz"]
    assert main(logs) == 0
    printed = capsys.readouterr().out
    assert printed == (RUNS / "failures.txt").read_text()
    assert "mujoco_cell-d23: timeout in transport" in printed and "dropped" not in printed
    assert "real_cell.jsonl.gz: 200 episodes, success 199, timeout 1; 11 with the cell behind" in printed


def test_a_missing_log_is_an_error_not_a_traceback(tmp_path, capsys):
    assert main([str(tmp_path / "none.jsonl")]) == 1
    assert "none.jsonl" in capsys.readouterr().err


def test_the_grasp_offsets_of_the_slim_logs_agree_with_the_committed_table(tmp_path, monkeypatch, capsys):
    """`--grasps` on the slim logs: a row per episode that kept its decisions (the failures and each log's first
    success), each the same as that episode's row of `grasps.csv` (computed from the full logs)."""
    import csv

    monkeypatch.chdir(RUNS)
    out = tmp_path / "grasps.csv"
    assert main(["mujoco_cell.jsonl.gz", "real_cell.jsonl.gz", "--grasps", str(out)]) == 0
    slim = list(csv.DictReader(out.open()))
    full = {(r["log"], r["episode"]): r for r in csv.DictReader((RUNS / "grasps.csv").open())}
    assert len(full) == 400 and len(slim) == 3 + 1 + 1 + 1  # each log's failures and its first success
    for row in slim:
        committed = full[(row["log"].removesuffix(".gz"), row["episode"])]
        assert (row["outcome"], row["grasp_offset_mm"]) == (committed["outcome"], committed["grasp_offset_mm"])


def test_the_grasp_offsets_by_outcome_are_what_the_committed_tables_say(capsys):
    from mrguide.replay.grasp_offsets import main as offsets

    for run, groups in (
        ("lift-drops-200", ("mujoco_cell", "real_cell")),
        ("sim2real", ("mujoco_exact", "mujoco_hmd", "real_exact", "real_hmd")),
    ):
        args = [str(RUNS.parent / run / "grasps.csv")] + [a for g in groups for a in ("--group", g)]
        assert offsets(args) == 0
        assert capsys.readouterr().out == (RUNS.parent / run / "grasp_offsets.txt").read_text()
    assert offsets([str(RUNS / "failures.txt"), "--group", "x"]) == 1  # not a grasps CSV: an error, no traceback


def test_fig8s_failures_are_what_its_slim_logs_say(capsys, monkeypatch):
    """Fig. 8's failures.txt, written from the full logs with paths relative to its directory: its slim logs keep the
    episodes' records but no decisions (120 logs would outweigh the checkout), so they give the same per-log outcomes
    and the same failed episodes with their outcomes; the phases, vacuum levels and offsets are the full logs'."""
    fig8 = RUNS.parent / "sim2real"
    monkeypatch.chdir(fig8)
    logs = sorted(str(p.relative_to(fig8)) for p in fig8.glob("guided/seed*/sim2real/log-*.jsonl.gz"))
    assert len(logs) == 120 and main(logs) == 0

    def outcomes(text: str) -> list[str]:
        return [line.split(" in ")[0] if line.startswith("seed") else line for line in text.splitlines()]

    slim = outcomes(capsys.readouterr().out.replace(".jsonl.gz", ".jsonl"))
    assert slim == outcomes((fig8 / "failures.txt").read_text()) and len(slim) == 120 + 137  # 137 of 1,500 failed


def test_the_episodes_whose_cell_ran_behind_the_clock_are_marked_as_not_judged(capsys):
    """Fig. 8's seed-0 MuJoCo HMD draw 4 at 4bbe186: two of its episodes ran the cell 0.10 and 0.19 s behind."""
    log = RUNS.parent / "own-process" / "fig8" / "seed0" / "log-mujoco_hmd-default-None-seed4-035545.jsonl.gz"
    assert main([str(log)]) == 0
    assert "10 episodes, success 9, timeout 1; 2 with the cell behind the clock (not judged)" in capsys.readouterr().out
