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
    cfg.write_text("[guidance]\nmarks = 'sideways'\n")
    assert main(["train", "--config", str(cfg), "--out", str(tmp_path / "r"), "--quiet"]) == 2
    assert "guidance.marks" in capsys.readouterr().err


def test_train_exports_the_target_actor(tmp_path):
    """The policy file holds the target actor's weights, not the online actor's."""
    import numpy as np
    import torch

    from mrguide.policies.checkpoint import read_checkpoint
    from mrguide.policies.ddpg import DDPG, DDPGConfig
    from mrguide.policies.networks import obs_scaling
    from mrguide.robot import load_robot

    out = tmp_path / "run"
    assert main(["train", "--steps", "300", "--out", str(out), "--quiet"]) == 0
    agent = DDPG(*obs_scaling(load_robot().workspace), 4, DDPGConfig())
    agent.load_state_dict(read_checkpoint(out / "checkpoint.pt")["agent"])
    obs = np.random.default_rng(0).uniform(-0.2, 0.6, (50, 11)).astype(np.float32)
    with torch.no_grad():
        target, online = (net(torch.as_tensor(obs)).numpy() for net in (agent.actor_target, agent.actor))
    exported = ExportedPolicy.load(out / "policy.npz").batch(obs)
    assert np.abs(exported - target).max() < 1e-5 < np.abs(exported - online).max()


def test_set_changes_any_config_key_for_the_run_and_refuses_a_bad_one(tmp_path, capsys):
    out = tmp_path / "run"
    argv = ["train", "--out", str(out), "--quiet", "--set", "train.total_steps=150", "--set", "ddpg.hidden=[24, 24]"]
    assert main(argv) == 0
    assert ExportedPolicy.load(out / "policy.npz").weights[0].shape[0] == 24  # the first layer's width
    assert main(["train", "--out", str(tmp_path / "bad"), "--quiet", "--set", "ddpg.lr_actor=-1"]) == 2
    assert "--set: ddpg.lr_actor" in capsys.readouterr().err and not (tmp_path / "bad").exists()


def test_config_show_prints_every_section_with_the_file_and_set_applied(tmp_path, capsys):
    import json

    cfg = tmp_path / "run.toml"
    cfg.write_text("[guidance]\nmarks = 'phases'\n\n[twin.reality_gap]\nobject_mass = 0.3\n")
    assert main(["config", "show", "--config", str(cfg), "--set", "ddpg.lr_actor=0.001"]) == 0
    shown = json.loads(capsys.readouterr().out)
    assert set(shown) == {"train", "ddpg", "sac", "guidance", "robot", "twin", "task"}  # [plant] is the cell's
    assert shown["ddpg"]["lr_actor"] == 0.001 and shown["guidance"]["marks"] == "phases"
    assert shown["twin"]["reality_gap"]["object_mass"] == 0.3 and shown["train"]["total_steps"] == 20_000
    assert main(["config", "show", "--set", "twin.reality_gap.object_mass=-1"]) == 2
    assert "object_mass" in capsys.readouterr().err
