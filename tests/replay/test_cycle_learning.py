"""`python -m mrguide.replay.cycle_learning`: a learning curve from dry-run cycle logs, scored on the truth the dry run
wrote; a log without scores is refused with its name."""

from __future__ import annotations

from mrguide.deploy.runlog import RunLog
from mrguide.replay.cycle_learning import cycles, main, trailing, trials


def _log(path, results: list[tuple[bool, int]]) -> None:
    """A cycle log: per cycle (at the goal, attempts), each cycle 6 s, the version rising by one per episode."""
    with RunLog(path, {"command": "deploy"}) as log:
        episode = 0
        for cycle, (at_goal, attempts) in enumerate(results):
            for _ in range(attempts):
                log.write("policy_version", episode=episode, version=episode)
                episode += 1
            outcomes = (["timeout"] * (attempts - 1) + ["success" if at_goal else "timeout"])[:attempts]
            log.write("cycle_end", cycle=cycle, placed=at_goal, outcomes=outcomes, cycle_s=6.0)
            log.write("scored", cycle=cycle, at_goal=at_goal, part=[0.5, 0.2, 0.025])


def test_the_curve_counts_parts_at_their_goal_against_the_cells_minutes(tmp_path):
    results = [(False, 2)] * 5 + [(True, 1)] * 95
    _log(tmp_path / "learn.jsonl", results)
    rows = cycles(tmp_path / "learn.jsonl")
    assert len(rows) == 100 and rows[-1].minutes == 10.0
    assert [r.version for r in rows[:7]] == [0, 2, 4, 6, 8, 10, 11]  # each cycle's first attempt
    assert [r.first_try for r in rows[4:6]] == [False, True]  # a timeout then a miss; a success at once
    assert trailing(rows, 20)[-1] == 1.0 and trailing(rows, 20)[4] == 0.0
    assert main([str(tmp_path / "learn.jsonl"), "--out", str(tmp_path / "out"), "--last", "50"]) == 0
    table = (tmp_path / "out" / "learning.md").read_text()
    assert "| 95 (95%) | 50 / 50 | 50 / 50 | cycle 53, 5.4 min | 10.0 | 104 | — |" in table  # 49 of 50 to cycle 53
    assert (tmp_path / "out" / "learning.png").stat().st_size > 0


def test_the_table_counts_the_versions_kept_and_dropped(tmp_path):
    _log(tmp_path / "learn.jsonl", [(True, 1)] * 3)
    with RunLog(tmp_path / "learn.jsonl", {"command": "deploy"}) as log:  # appends
        for verdict in ("dropped", "kept", "dropped", "dropped"):
            log.write("policy_trial", episode=0, version=1, verdict=verdict, acting=0)
    assert trials(tmp_path / "learn.jsonl") == "1 / 3"


def test_a_log_without_scores_is_refused(tmp_path, capsys):
    with RunLog(tmp_path / "robot.jsonl", {"command": "deploy"}) as log:
        log.write("cycle_end", cycle=0, placed=True, outcomes=["success"], cycle_s=5.0)
    assert main([str(tmp_path / "robot.jsonl"), "--out", str(tmp_path / "out")]) == 1
    assert "no scored cycles" in capsys.readouterr().err


def test_a_cycle_without_an_attempt_keeps_the_version_acted_with_last(tmp_path):
    _log(tmp_path / "alarm.jsonl", [(True, 1), (True, 2), (False, 0)])  # the last cycle's part never came
    assert [r.version for r in cycles(tmp_path / "alarm.jsonl")] == [0, 1, 2]


def test_the_committed_on_cell_table_is_what_its_logs_say(tmp_path):
    from pathlib import Path

    results = Path(__file__).parents[2] / "docs" / "results" / "on-cell"
    logs = [str(results / f"{name}-seed0.jsonl.gz") for name in ("frozen", "learn-e0", "learn-e002")]
    assert main([*logs, "--out", str(tmp_path)]) == 0
    assert (tmp_path / "learning.md").read_text() == (results / "learning.md").read_text()


def test_the_committed_three_seed_table_is_what_its_logs_say(tmp_path):
    from pathlib import Path

    results = Path(__file__).parents[2] / "docs" / "results" / "on-cell-seeds"
    logs = [str(results / f"{run}-seed{s}.jsonl.gz") for run in ("frozen", "learn", "learn0") for s in range(3)]
    assert main([*logs, "--out", str(tmp_path)]) == 0
    assert (tmp_path / "learning.md").read_text() == (results / "learning.md").read_text()
