"""`mrguide train` refuses bad numbers and unsafe restarts with one line on stderr and exit 2."""

import pytest

from mrguide.cli import main


@pytest.mark.parametrize("argv, words", [
    (["--steps", "0"], "--steps: must be a whole number >= 1"),
    (["--steps", "-5"], "--steps: must be a whole number >= 1"),
    (["--stop-after", "0"], "--stop-after: must be a whole number >= 1"),
    (["--stop-after", "-1"], "--stop-after: must be a whole number >= 1"),
    (["--seed", "-3"], "--seed: must be a whole number >= 0"),
    (["--seed", "1.5"], "--seed: not a whole number"),
    (["--expert", "live", "--annotation-timeout", "nan"], "--annotation-timeout: must be finite"),
    (["--expert", "live", "--port", "-1"], "--port: must be a whole number >= 0"),
    (["--expert", "telepathy"], "invalid choice"),
])
def test_bad_numbers_are_refused_at_parse_time(tmp_path, capsys, argv, words):
    with pytest.raises(SystemExit) as exc:
        main(["train", "--out", str(tmp_path / "r"), *argv])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err
    assert not (tmp_path / "r").exists()


def test_a_run_that_never_checkpointed_is_not_appended_to(tmp_path, capsys):
    out = tmp_path / "r"
    out.mkdir()
    (out / "metrics.csv").write_text("step\n5\n")
    (out / "annotations.jsonl").write_text("")
    assert main(["train", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "never checkpointed" in err and "metrics.csv, annotations.jsonl" in err
    assert (out / "metrics.csv").read_text() == "step\n5\n"


def test_resume_without_a_checkpoint_is_refused(tmp_path, capsys):
    assert main(["train", "--out", str(tmp_path / "r"), "--resume", "--quiet"]) == 2
    assert "no checkpoint at" in capsys.readouterr().err
