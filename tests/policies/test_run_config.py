"""One run configuration, parsed once: `mrguide train` reads its file once, and a checkpoint's fingerprint covers
exactly what training reads — a cell's [plant] may change under a resumed DDPG run, its learner's settings may not."""

from __future__ import annotations

import pytest

from mrguide import config as config_module
from mrguide.cli import main
from mrguide.config import ConfigError
from mrguide.policies.train_config import RunConfig

#: No update (learning starts after the run) and one evaluation episode: what is tested is the config, not learning.
RUN = (
    "[train]\nlearning_starts = 100000\neval_episodes = 1\n\n[ddpg]\nhidden = [16, 16]\n\n"
    "[plant.mujoco]\nseal_gap = {gap}\n"
)


def test_train_reads_its_file_once_and_resumes_across_a_cell_change_but_not_a_learner_change(
    tmp_path, monkeypatch, capsys
):
    cfg = tmp_path / "run.toml"
    cfg.write_text(RUN.format(gap=0.001))
    reads = []
    real = config_module.load_toml
    monkeypatch.setattr(config_module, "load_toml", lambda path: reads.append(str(path)) or real(path))
    out = str(tmp_path / "run")
    argv = ["train", "--config", str(cfg), "--out", out, "--quiet", "--steps", "300"]
    assert main([*argv, "--stop-after", "100"]) == 0
    assert reads == [str(cfg)]
    cfg.write_text(RUN.format(gap=0.002))  # the MuJoCo cell's physics: training never reads it
    assert main([*argv, "--resume", "--stop-after", "200"]) == 0
    assert main([*argv, "--resume", "--set", "ddpg.lr_actor=0.002"]) == 2
    assert "sections differ: ddpg" in capsys.readouterr().err


def test_the_fingerprint_holds_the_trained_learners_section_only():
    ddpg = RunConfig().fingerprint({})
    assert "ddpg" in ddpg and "sac" not in ddpg and "plant" not in ddpg["env"]
    sac = RunConfig.load(None).with_overrides({"train.learner": "sac"}).fingerprint({})
    assert "sac" in sac and "ddpg" not in sac


def test_a_learner_nobody_registered_and_an_unknown_section_are_refused(tmp_path):
    with pytest.raises(ConfigError, match=r"train\.learner = 'nobody'"):
        RunConfig.load(None).with_overrides({"train.learner": "nobody"})
    bad = tmp_path / "bad.toml"
    bad.write_text("[ddgp]\nhidden = [16, 16]\n")
    with pytest.raises(ConfigError, match=r"unknown section \[ddgp\]"):
        RunConfig.load(bad)
    with pytest.raises(ConfigError, match=r"'plant\.engine'"):
        RunConfig().with_overrides({"plant.engine": "mujoco"}, "--set")
