"""Arm files: the shipped UR5 and UR10 load (from any directory), FK/IK round trips on the UR10, overrides
from a run config, and a bad arm file is one RobotSpecError line naming the file and the key."""

from __future__ import annotations

import itertools
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mrguide.motion.kinematics import Kinematics
from mrguide.robot import R_TOOL_DOWN, RobotConfig, RobotSpecError, load_robot, load_robot_config, shipped_arms
from mrguide.twin.env import EnvConfig

UR5_TOML = Path(shipped_arms()["ur5"]).read_text()
REPO = Path(__file__).resolve().parents[1]


def test_ur10_arm_loads_with_its_own_urdf_limits_and_identity():
    ur5, ur10 = load_robot(), load_robot(RobotConfig(name="ur10"))
    assert (ur5.name, ur10.name) == ("ur5", "ur10")
    assert ur10.urdf_path.name == "ur10_robot.urdf" and ur10.urdf_path.is_file()
    assert ur10.dof == 6 and ur10.node_ids == (3, 4, 5, 6, 7, 8)
    assert ur10.q_upper[2] == pytest.approx(3.1) and ur5.q_upper[2] == pytest.approx(2.8)
    assert ur10.fingerprint != ur5.fingerprint  # same joints, cup and box: the URDF chain differs
    assert load_robot(RobotConfig(name="ur10")).fingerprint == ur10.fingerprint  # deterministic


def test_shipped_arms_are_found_from_any_directory(tmp_path):
    code = (
        "from mrguide.robot import load_robot, RobotConfig; print(load_robot(RobotConfig(name='ur10')).urdf_path.name)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        env={"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"},
        timeout=120,
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "ur10_robot.urdf"


def test_ur10_fk_ik_round_trip_and_the_whole_workspace_box_is_reachable_pointing_down():
    spec = load_robot(RobotConfig(name="ur10"))
    kin = Kinematics(spec)
    home = kin.fk(spec.q_home)
    np.testing.assert_allclose(home[:3, :3], R_TOOL_DOWN, atol=1e-3)  # home points the cup down
    assert spec.workspace.contains(home[:3, 3])
    rng = np.random.default_rng(0)
    for _ in range(40):  # random poses near home: FK -> IK -> FK gives the same TCP pose
        q = np.clip(spec.q_home + rng.normal(0, 0.3, 6), spec.q_lower, spec.q_upper)
        T = kin.fk(q)
        q2 = kin.ik(T[:3, 3], spec.q_home, T[:3, :3])
        np.testing.assert_allclose(kin.fk(q2), T, atol=1e-3)
    ws, q = spec.workspace, spec.q_home
    for corner in itertools.product(*zip(ws.lo, ws.hi)):
        q = kin.ik(np.array(corner), q)
        np.testing.assert_allclose(kin.tcp_position(q), corner, atol=1e-3)
        assert spec.within_limits(q)


def test_run_config_selects_an_arm_file_relative_to_itself_and_overrides_it(tmp_path):
    (tmp_path / "arms").mkdir()
    (tmp_path / "arms" / "mine.toml").write_text(UR5_TOML.replace('name = "ur5"', 'name = "mine"'))
    cfg = tmp_path / "run.toml"
    cfg.write_text('[robot]\nfile = "arms/mine.toml"\ntool_offset = 0.12\n')
    spec = load_robot(load_robot_config(cfg))
    assert spec.name == "mine" and spec.T_flange_tcp[2, 3] == pytest.approx(0.12)
    assert EnvConfig.load(cfg).robot.file == str(tmp_path / "arms" / "mine.toml")
    assert spec.fingerprint != load_robot(RobotConfig(file=str(tmp_path / "arms" / "mine.toml"))).fingerprint


def _edit(old: str, new: str):
    def change(text: str) -> str:
        assert old in text, old
        return text.replace(old, new)

    return change


BAD_ARMS = [
    # (id, change of the UR5 arm file, words in the message besides the file)
    ("bad TOML", lambda t: t + "\n[urdf\n", ["not valid TOML"]),
    ("missing key", _edit('flange_frame = "tool0"\n', ""), ["flange_frame"]),
    ("unknown key", lambda t: "tool_ofset = 0.1\n" + t, ["tool_ofset"]),
    ("wrong type", _edit("tool_offset = 0.10", 'tool_offset = "10 cm"'), ["tool_offset", "10 cm"]),
    ("nan limit", _edit("v_max = [1.5,", "v_max = [nan,"), ["v_max[0]", "nan"]),
    ("five limits", _edit("a_max = [6.0, ", "a_max = ["), ["a_max", "expected 6 finite values"]),
    ("home outside", _edit("q_home = [0.0,", "q_home = [3.0,"), ["q_home", "outside the joint limits"]),
    (
        "unknown joint",
        _edit('"elbow_joint", "wrist_1', '"knee_joint", "wrist_1'),
        ["joints", "knee_joint", "movable joints"],
    ),
    ("node map misses a joint", _edit("wrist_3_joint = 8\n", ""), ["can_nodes", "wrist_3_joint"]),
    ("duplicate node", _edit("wrist_3_joint = 8", "wrist_3_joint = 3"), ["can_nodes", "distinct"]),
    ("node 200", _edit("wrist_3_joint = 8", "wrist_3_joint = 200"), ["can_nodes", "1..127"]),
    ("flange not in URDF", _edit('flange_frame = "tool0"', 'flange_frame = "tool9"'), ["flange_frame", "tool9"]),
    (
        "no such example-robot-data URDF",
        _edit("ur5_robot.urdf", "ur7_robot.urdf"),
        ["ur7_robot.urdf", "example-robot-data"],
    ),
    (
        "URDF file not found",
        _edit('example_robot_data = "ur_description/urdf/ur5_robot.urdf"', 'file = "nope.urdf"'),
        ["urdf.file", "nope.urdf"],
    ),
    (
        "both URDF sources",
        _edit('example_robot_data = "', 'file = "x.urdf"\nexample_robot_data = "'),
        ["urdf", "exactly one"],
    ),
    ("workspace inverted", _edit("high = [0.65, 0.40, 0.35]", "high = [0.25, 0.40, 0.35]"), ["workspace", "high"]),
]


@pytest.mark.parametrize("change, words", [c[1:] for c in BAD_ARMS], ids=[c[0] for c in BAD_ARMS])
def test_a_bad_arm_file_is_one_line_naming_the_file_and_the_key(tmp_path, change, words):
    arm = tmp_path / "arm.toml"
    arm.write_text(change(UR5_TOML))
    with pytest.raises(RobotSpecError) as info:
        load_robot(RobotConfig(file=str(arm)))
    message = str(info.value)
    assert "\n" not in message and str(arm) in message
    for word in words:
        assert word in message


def test_unknown_arm_and_missing_arm_file_are_one_clear_message(tmp_path):
    with pytest.raises(RobotSpecError, match=r"unknown robot 'kuka'.*known robots: ur10, ur5"):
        load_robot(RobotConfig(name="kuka"))
    with pytest.raises(RobotSpecError, match=r"unknown robot '../ur5'"):
        load_robot(RobotConfig(name="../ur5"))
    with pytest.raises(RobotSpecError, match=r"robot.file: arm file not found: .*none.toml"):
        load_robot(RobotConfig(file=str(tmp_path / "none.toml")))
