"""Smoke run of the real `mrguide train` command on a tiny budget, then resume."""

from mrguide.cli import main
from mrguide.deploy.policy import ExportedPolicy


def test_train_smoke_and_resume(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["train", "--steps", "200", "--out", str(out), "--quiet"]) == 0
    assert "trained 2" in capsys.readouterr().out
    pol = ExportedPolicy.load(out / "policy.npz")
    assert pol.metadata["trained"]["guidance"] is True
    # refuses to overwrite, resumes on request
    assert main(["train", "--steps", "200", "--out", str(out), "--quiet"]) == 2
    assert main(["train", "--steps", "300", "--out", str(out), "--quiet", "--resume"]) == 0
    assert "trained 3" in capsys.readouterr().out


def test_bad_config_is_one_clear_error(tmp_path, capsys):
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[guidance]\nmode = 'sideways'\n")
    assert main(["train", "--config", str(cfg), "--out", str(tmp_path / "r"), "--quiet"]) == 2
    assert "guidance.mode" in capsys.readouterr().err
