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
    assert main(["train", "--config", str(cfg), "--steps", "300", "--out", str(out), "--quiet"]) == 0, capsys.readouterr().err
    with (out / "metrics.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    assert int(rows[-1]["step"]) >= 300
    demos = [r for r in rows if r["kind"] == "expert"]
    assert demos and any(r["outcome"] == "success" for r in demos)  # the expert places the cube with the UR10
    ur10 = load_robot(RobotConfig(name="ur10"))
    policy = ExportedPolicy.load(out / "policy.npz", ur10)
    assert policy.metadata["robot"] == {"name": "ur10", "fingerprint": ur10.fingerprint, "joints": list(ur10.joint_names)}
    with pytest.raises(PolicyFileError, match="exported for arm 'ur10'"):
        ExportedPolicy.load(out / "policy.npz", load_robot())
