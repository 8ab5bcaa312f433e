"""The UR10 trains in the twin: a short guided run of the real `mrguide train` command with the UR10 arm,
whose expert demonstrations succeed, and whose exported policy records the UR10 and runs only on it."""

import csv

import pytest

from mrguide.cli import main
from mrguide.deploy.policy import ExportedPolicy, PolicyFileError
from mrguide.robot import RobotConfig, load_robot

TINY_UR10 = """
[robot]
name = "ur10"
[train]
learning_starts = 64
batch_size = 32
eval_every = 10000
checkpoint_every = 10000
[ddpg]
hidden = [16, 16]
[guidance]
intake_steps = 400
"""


def test_short_guided_training_with_the_ur10(tmp_path, capsys):
    cfg, out = tmp_path / "ur10.toml", tmp_path / "run"
    cfg.write_text(TINY_UR10)
    assert main(["train", "--config", str(cfg), "--steps", "300", "--out", str(out), "--quiet"]) == 0, (
        capsys.readouterr().err
    )
    with (out / "metrics.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert int(rows[-1]["step"]) >= 300
    demos = [r for r in rows if r["kind"] == "expert"]
    assert demos and any(r["outcome"] == "success" for r in demos)  # the expert places the cube with the UR10
    ur10 = load_robot(RobotConfig(name="ur10"))
    policy = ExportedPolicy.load(out / "policy.npz", ur10)
    assert policy.metadata["robot"] == {
        "name": "ur10",
        "fingerprint": ur10.fingerprint,
        "joints": list(ur10.joint_names),
    }
    with pytest.raises(PolicyFileError, match="exported for arm 'ur10'"):
        ExportedPolicy.load(out / "policy.npz", load_robot())
    # the checkpoint belongs to the UR10 run: resuming it with the UR5 is refused, with the UR10 it goes on
    ur5_cfg = tmp_path / "ur5.toml"
    ur5_cfg.write_text(TINY_UR10.replace('name = "ur10"', 'name = "ur5"'))
    assert main(["train", "--config", str(ur5_cfg), "--steps", "350", "--out", str(out), "--quiet", "--resume"]) == 2
    assert "different configuration (sections differ: env)" in capsys.readouterr().err
    assert main(["train", "--config", str(cfg), "--steps", "350", "--out", str(out), "--quiet", "--resume"]) == 0


def test_checkpoints_record_the_arm_as_before_arm_files():
    """A UR5 run records the arm as the [robot] defaults did, so runs checkpointed before arm files resume."""
    from mrguide.policies.train_config import arm_record

    assert arm_record(load_robot()) == {
        "name": "ur5",
        "tool_offset": 0.1,
        "q_lower": (-2.6, -3.0, -2.8, -3.8, -2.8, -3.2),
        "q_upper": (2.6, -0.1, 2.8, 0.6, -0.3, 3.2),
        "v_max": (1.5, 1.5, 1.5, 2.0, 2.0, 2.0),
        "a_max": (6.0, 6.0, 6.0, 8.0, 8.0, 8.0),
        "j_max": (60.0, 60.0, 60.0, 80.0, 80.0, 80.0),
        "q_home": (0.0, -1.5707963, 1.5707963, -1.5707963, -1.5707963, 0.0),
        "workspace": {"low": (0.3, -0.2, 0.045), "high": (0.65, 0.4, 0.35)},
    }
