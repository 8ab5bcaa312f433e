"""`mrguide expert`: bad numbers refused at parse time; a small run reports its seeds."""

from __future__ import annotations

import pytest


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--episodes", "-1"], ["--episodes", "'-1'"]),
        (["--episodes", "0"], ["--episodes", "'0'"]),
        (["--episodes", "2.5"], ["--episodes", "'2.5'"]),
        (["--seed", "-1"], ["--seed", "'-1'"]),
        (["--seed", "nan"], ["--seed", "'nan'"]),
    ],
)
def test_bad_numbers_are_refused_at_parse_time(run_cli, argv, words):
    run_cli(["expert", "--quiet", *argv]).assert_refused(*words)


def test_one_episode(run_cli):
    result = run_cli(["expert", "--quiet", "--episodes", 1, "--seed", 3])
    assert result.code == 0, result.err
    assert "over 1 episodes (seeds 3..3)" in result.out
