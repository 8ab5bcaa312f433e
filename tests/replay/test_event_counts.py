"""`python -m mrguide.replay.event_counts`: bad input is an error, not a traceback. (The test of its committed counts
read `docs/results/main5k-deploy/`, superseded and moved out of the tree: `git show 4dc9171:docs/results/main5k-deploy/`.)"""

from __future__ import annotations

from mrguide.replay.event_counts import main


def test_a_missing_log_is_an_error_not_a_traceback(tmp_path, capsys):
    assert main([str(tmp_path / "none.jsonl")]) == 1
    assert "none.jsonl" in capsys.readouterr().err
