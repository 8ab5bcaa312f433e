"""A policy runs only on the arm it was exported for: UR5 policies are refused on the UR10 and the other way
round (loader, `deploy`, `sim2real`, before anything is enabled); files from before arm identities are taken
for the UR5 only. The UR10 dry-runs over the simulated bus."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np
import pytest

from mrguide.cli import main
from mrguide.config import to_dict
from mrguide.deploy.policy import ExportedPolicy, PolicyFileError
from mrguide.deploy.runlog import read_log
from mrguide.drivers.cobot import Cobot
from mrguide.robot import RobotConfig, load_robot
from mrguide.task import TaskConfig
from mrguide.twin.env import EnvConfig

REPO = Path(__file__).resolve().parents[2]
HORIZON = 4
BIASES = np.array([0.5, -0.4, 0.2, -1.0])  # a constant offset from the anchor (0.5 m · tanh of these), vacuum off


def _arm(name: str):
    return load_robot(RobotConfig(name=name))


@pytest.fixture
def exported(tmp_path, policy_file):
    """exported(arm name or None for no arm, **metadata changes) -> policy file (one layer, constant offset)."""

    def write(name: str | None, **changes) -> Path:
        robot = {} if name is None else {"robot": {"name": name, "fingerprint": _arm(name).fingerprint}}
        return policy_file(
            tmp_path / f"{name}.npz",
            task=to_dict(TaskConfig(horizon=HORIZON)),
            arrays={"b0": BIASES, "b0_carry": BIASES},
            **robot,
            **changes,
        )

    return write


@pytest.mark.parametrize("trained, configured", [("ur5", "ur10"), ("ur10", "ur5")])
def test_a_policy_for_one_arm_is_refused_on_the_other(exported, trained, configured):
    path = exported(trained)
    assert ExportedPolicy.load(path, _arm(trained), TaskConfig(horizon=HORIZON)).metadata["robot"]["name"] == trained
    with pytest.raises(
        PolicyFileError, match=f"exported for arm '{trained}', the configuration drives arm '{configured}'"
    ):
        ExportedPolicy.load(path, _arm(configured), TaskConfig(horizon=HORIZON))


def test_same_name_with_another_tool_is_refused_by_the_fingerprint(exported):
    longer_cup = load_robot(RobotConfig(name="ur5", tool_offset=0.12))
    with pytest.raises(PolicyFileError, match=r"fingerprint .*TCP offset"):
        ExportedPolicy.load(exported("ur5"), longer_cup, TaskConfig(horizon=HORIZON))


def test_a_policy_without_an_arm_is_taken_for_the_ur5_only(exported, caplog):
    path = exported(None)
    with caplog.at_level(logging.WARNING, logger="mrguide.deploy.policy"):
        ExportedPolicy.load(path, _arm("ur5"), TaskConfig(horizon=HORIZON))
    assert "records no arm" in caplog.text and "Re-export" in caplog.text
    with pytest.raises(
        PolicyFileError, match=r"records no arm .*drives 'ur10': train and export a policy for this arm"
    ):
        ExportedPolicy.load(path, _arm("ur10"), TaskConfig(horizon=HORIZON))
    with pytest.raises(PolicyFileError, match="metadata robot 'ur5' is not an object"):
        ExportedPolicy.load(exported(None, robot="ur5"), _arm("ur5"))


def _config(tmp_path: Path, arm: str) -> Path:
    cfg = tmp_path / f"{arm}.toml"
    cfg.write_text(
        f'[robot]\nname = "{arm}"\n[task]\nhorizon = {HORIZON}\n'
        f'[deploy]\nbus_config = "bus.toml"\nepisodes = 1\nlog_dir = "{tmp_path / "logs"}"\n'
    )
    (tmp_path / "bus.toml").write_text(f'[bus]\ninterface = "virtual"\nchannel = "arm-{tmp_path.name}"\n')
    return cfg


@pytest.mark.parametrize("trained, configured", [("ur5", "ur10"), ("ur10", "ur5")])
def test_deploy_refuses_a_policy_of_another_arm_before_enabling(
    tmp_path, exported, monkeypatch, capsys, trained, configured
):
    enabled = []
    monkeypatch.setattr(Cobot, "enable", lambda self, timeout=None: enabled.append(1))
    code = main(
        [
            "deploy",
            "--policy",
            str(exported(trained)),
            "--config",
            str(_config(tmp_path, configured)),
            "--dry-run",
            "--quiet",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and enabled == []
    assert err.startswith("mrguide deploy: ") and err.count("\n") == 1
    assert f"exported for arm '{trained}'" in err and f"drives arm '{configured}'" in err


def test_sim2real_refuses_a_real_cell_with_another_arm(tmp_path, exported, capsys):
    train_cfg = _config(tmp_path, "ur10")
    code = main(
        [
            "sim2real",
            "--policy",
            str(exported("ur10")),
            "--config",
            str(train_cfg),
            "--real-config",
            str(REPO / "configs" / "cells" / "real_cell.toml"),
            "--out",
            str(tmp_path / "s2r"),
            "--quiet",
        ]
    )
    assert code == 2
    assert "exported for arm 'ur10', the configuration drives arm 'ur5'" in capsys.readouterr().err
    assert not (tmp_path / "s2r").exists()


def test_ur10_deploy_dry_run_over_the_simulated_bus(tmp_path, exported, capsys):
    log = tmp_path / "run.jsonl"
    code = main(
        [
            "deploy",
            "--policy",
            str(exported("ur10")),
            "--config",
            str(_config(tmp_path, "ur10")),
            "--dry-run",
            "--log",
            str(log),
            "--quiet",
        ]
    )
    assert code == 0, capsys.readouterr().err
    ur10, ur5 = _arm("ur10"), _arm("ur5")
    steps = [r for r in read_log(log) if r["kind"] == "decision" and "setpoints" in r]
    assert len(steps) == HORIZON
    # the part's centre plus the offset, in the UR10's box (the part does not move: the vacuum stays off)
    expected = ur10.workspace.clamp(np.array(steps[0]["obs"][5:8]) + 0.5 * np.tanh(BIASES[:3]))[0]
    assert all(np.allclose(r["target"], expected, atol=2e-4) for r in steps)  # the log keeps 0.1 mm
    first = np.array(steps[0]["setpoints"][0])  # streamed from the UR10's home, not the UR5's
    assert np.max(np.abs(first - ur10.q_home)) < 0.05 < np.max(np.abs(first - ur5.q_home))


def test_ur10_expert_succeeds_through_the_full_stack(run_dry):
    summary, _, cell = run_dry(episodes=2, seed=3, env_cfg=EnvConfig(robot=RobotConfig(name="ur10")))
    assert cell.scene.spec.name == "ur10" and cell.cobot.robot.name == "ur10"
    assert summary.stopped is None and summary.successes == 2, summary.text()
