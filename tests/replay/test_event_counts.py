"""`python -m mrguide.replay.event_counts`: the re-seats of the main job's policy in the deploy conditions, recomputed from its slim
logs exactly as `reseats.txt` beside them says (and as the results page quotes them)."""

from __future__ import annotations

from pathlib import Path

from mrguide.replay.event_counts import main

RUNS = Path(__file__).parents[2] / "docs" / "results" / "main5k-deploy"


def test_the_committed_reseat_counts_are_what_the_logs_say(capsys, monkeypatch):
    monkeypatch.chdir(RUNS)
    logs = sorted(p.name for p in RUNS.glob("log-*.jsonl.gz"))
    assert len(logs) == 12 and main(logs) == 0
    printed = capsys.readouterr().out
    assert printed == (RUNS / "reseats.txt").read_text()
    assert "log-real_exact-default-None-seed0-074455.jsonl.gz: 10 episodes; 0 with reseat (none)" in printed


def test_a_missing_log_is_an_error_not_a_traceback(tmp_path, capsys):
    assert main([str(tmp_path / "none.jsonl")]) == 1
    assert "none.jsonl" in capsys.readouterr().err
