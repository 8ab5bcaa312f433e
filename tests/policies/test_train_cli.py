"""`mrguide train` refuses bad numbers and unsafe restarts with one line on stderr and exit 2."""

import pytest

from mrguide.cli import main


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--steps", "0"], "--steps: must be a whole number >= 1"),
        (["--steps", "-5"], "--steps: must be a whole number >= 1"),
        (["--stop-after", "0"], "--stop-after: must be a whole number >= 1"),
        (["--stop-after", "-1"], "--stop-after: must be a whole number >= 1"),
        (["--seed", "-3"], "--seed: must be a whole number >= 0"),
        (["--seed", "1.5"], "--seed: not a whole number"),
        (["--expert", "live", "--annotation-timeout", "nan"], "--annotation-timeout: must be finite"),
        (["--expert", "live", "--port", "-1"], "--port: must be a whole number >= 0"),
        (["--expert", "telepathy"], "invalid choice"),
    ],
)
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


@pytest.mark.parametrize(
    "toml, words",
    [
        ("[train]\neval_episodes = 0", "train.eval_episodes = 0"),
        ("[train]\ncheckpoint_every = 0", "train.checkpoint_every = 0"),
        ("[train]\ntorch_threads = 0", "train.torch_threads = 0"),
        ("[train]\nbuffer_size = 0", "train.buffer_size = 0"),
        ("[train]\nbatch_size = 2.5", "batch_size = 2.5: expected an integer"),
        ("[ddpg]\nlr_actor = -0.001", "ddpg.lr_actor = -0.001"),
        ("[ddpg]\nhidden = [0, 96]", "ddpg.hidden"),
        ("[guidance]\ndelta = 0", "guidance.delta = 0"),
        ("[guidance.noise]\nsigma = nan", "noise.sigma = nan: must be finite"),
        ("[guidance.noise]\nbias = [0, 0, inf]", "noise.bias[2] = inf: must be finite"),
        ("[guidance]\nsource = 'file'", "guidance.source = 'file' needs guidance.annotation_file"),
        ("[guidance]\nsource = 'file'\nannotation_file = 'missing.jsonl'", "annotation file not found"),
        ("[guidance]\nturbo = true", "turbo"),
        ("[robot]\nname = 'ur99'", "unknown robot 'ur99'"),
        ("[robot]\nq_home = [0, 0, 0, 0, 0, 0]", "q_home lies outside the joint limits"),
        ("[twin.reality_gap]\nactuator_lag = nan", "actuator_lag = nan: must be finite"),
        ("[twin]\ncontrol_period = 0", "twin.control_period = 0"),
        ("[task]\nhorizon = 0", "task.horizon"),
    ],
)
def test_bad_config_values_end_in_one_line_naming_the_key(tmp_path, capsys, toml, words):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(toml + "\n")
    assert main(["train", "--config", str(cfg), "--out", str(tmp_path / "r"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and err.startswith("mrguide train: ") and len(err.splitlines()) == 1, err
    assert not (tmp_path / "r" / "metrics.csv").exists()


@pytest.mark.parametrize(
    "record, words",
    [
        ("", "no annotations in the file"),
        ('{"obs": [0.1], "target": [0.5, 0, 0.1], "grip": 1}', "11 finite numbers"),
        ('"just a string"', "JSON object"),
        ('{"obs": OBS, "target": [0.5, NaN, 0.1], "grip": 1}', "3 finite numbers"),
        ('{"obs": OBS, "target": [0.5, 0, 0.1], "grip": null}', "gripper command"),
    ],
)
def test_bad_annotation_files_are_refused_naming_file_and_line(tmp_path, capsys, record, words):
    obs = str([0.5, 0.1, 0.3, -1.0, 0.0, 0.5, -0.1, 0.025, 0.5, 0.2, 0.025])
    ann = tmp_path / "ann.jsonl"
    ann.write_text((record.replace("OBS", obs) + "\n\n") if record else "")
    cfg = tmp_path / "file.toml"
    cfg.write_text(f"[guidance]\nsource = 'file'\nannotation_file = '{ann}'\n")
    assert main(["train", "--config", str(cfg), "--out", str(tmp_path / "r"), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert words in err and str(ann) in err and len(err.splitlines()) == 1, err


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--seeds", "0"], "--seeds"),
        (["--workers", "0"], "--workers"),
        (["--steps", "-1"], "--steps"),
    ],
)
def test_experiment_numbers_refused(tmp_path, capsys, argv, words):
    with pytest.raises(SystemExit) as exc:
        main(["experiment", "learning-curves", "--out", str(tmp_path / "x"), *argv])
    assert exc.value.code == 2 and words in capsys.readouterr().err


def test_experiment_config_refused_before_any_run(tmp_path, capsys):
    cfg = tmp_path / "e.toml"
    cfg.write_text('[experiment]\nvariants = ["guided", "turbo"]\n')
    assert main(["experiment", "learning-curves", "--config", str(cfg), "--out", str(tmp_path / "x")]) == 2
    assert "experiment.variants" in capsys.readouterr().err and not (tmp_path / "x").exists()
    cfg.write_text('[experiment]\noverrides = {"guidance.noise.sigma" = -1}\n')
    assert main(["experiment", "learning-curves", "--config", str(cfg), "--out", str(tmp_path / "x")]) == 2
    assert "guidance.noise.sigma = -1" in capsys.readouterr().err and not (tmp_path / "x").exists()


def test_an_option_given_double_dash_is_refused_not_an_empty_list(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["train", "--steps=--"])
    assert exc.value.code == 2 and "--steps: expected a value, got '--'" in capsys.readouterr().err


def test_a_refusal_is_exactly_one_line_on_stderr_in_a_real_process(tmp_path):
    """Nothing else reaches stderr either (PyBullet's import banner is kept off it)."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    cfg = tmp_path / "bad.toml"
    cfg.write_text("[train]\neval_episodes = 0\n")
    env = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
    res = subprocess.run(
        [sys.executable, "-m", "mrguide.cli", "train", "--config", str(cfg), "--out", str(tmp_path / "r")],
        capture_output=True,
        text=True,
        env=env,
        timeout=120,
    )
    assert res.returncode == 2 and res.stdout == ""
    assert res.stderr.splitlines() == [
        f"mrguide train: {cfg} [train]: train.eval_episodes = 0: expected an integer in [1, 100000]"
    ]
