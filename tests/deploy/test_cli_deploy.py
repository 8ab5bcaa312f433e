"""`mrguide deploy` refuses a bad policy before any drive is enabled, and a real bus without confirmation."""

import numpy as np

from mrguide.cli import main
from mrguide.drivers.cobot import Cobot


def test_bad_policy_refused_before_enable(tmp_path, monkeypatch, capsys):
    enabled = []
    monkeypatch.setattr(Cobot, "enable", lambda self, timeout=None: enabled.append(1))
    bad = tmp_path / "bad.npz"
    np.savez(bad, W0=np.zeros((4, 11)))
    assert main(["deploy", "--policy", str(bad), "--dry-run", "--quiet"]) == 2
    assert "no metadata" in capsys.readouterr().err
    assert enabled == []


def test_real_bus_needs_confirmation(tmp_path, monkeypatch, capsys):
    from mrguide.policies.ddpg import DDPG, DDPGConfig
    from mrguide.policies.export import export_actor
    from mrguide.policies.train import obs_scaling
    from mrguide.robot import Workspace
    from mrguide.task import TaskConfig

    connected = []
    monkeypatch.setattr(Cobot, "connect", lambda self: connected.append(1))
    pol = export_actor(DDPG(*obs_scaling(Workspace()), 4, DDPGConfig()).actor, tmp_path / "p.npz", Workspace(), TaskConfig(), 0.1)
    bus = tmp_path / "bus.toml"
    bus.write_text('[bus]\ninterface = "socketcan"\nchannel = "can0"\n')
    cfg = tmp_path / "cfg.toml"
    cfg.write_text('[deploy]\nbus_config = "bus.toml"\n')
    assert main(["deploy", "--policy", str(pol), "--config", str(cfg), "--quiet"]) == 2
    assert "--enable-drives" in capsys.readouterr().err
    assert connected == []
