"""Bus description: the repo's TOML, defaults, and clear errors for bad values."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from mrguide.config import ConfigError
from mrguide.drivers.config import (
    BusConfig,
    CobotBusConfig,
    JointDriveConfig,
    LimitOverrides,
    TimingConfig,
    load_cobot_bus_config,
    resolve_limits,
)
from mrguide.drivers.conversion import JointConversion
from tests.config_keys import undocumented

REPO_TOML = Path(__file__).resolve().parents[2] / "configs" / "devices" / "cobot_bus.toml"


def test_repo_toml_documents_every_setting_and_takes_the_arm_limits(robot):
    """Every setting of the bus description is in the shipped file (the reference users copy), except the node
    IDs, which come from the arm file; the file loads and its limits are the arm's."""
    assert undocumented(CobotBusConfig, "", REPO_TOML.read_text()) == {"joints.node_id"}
    config = load_cobot_bus_config(REPO_TOML)
    assert [j.node_id for j in config.joints] == [3, 4, 5, 6, 7, 8]
    assert config.vacuum.node_id == 16
    assert config.timing.control_period == pytest.approx(0.004)
    limits = resolve_limits(config, robot)
    np.testing.assert_array_equal(limits.q_lower, robot.q_lower)
    np.testing.assert_array_equal(limits.v_max, robot.v_max)


@pytest.mark.parametrize(
    "toml, words",
    [
        ('[bus]\ninterface = "cann"\n', ["bus.interface", "cann"]),
        ("[bus]\nbitrate = 123456\n", ["bus.bitrate", "123456"]),
        ("[timing]\ncontrol_period = 0.2\n", ["timing.control_period"]),
        ("[timing]\nheartbeat_period = 0.0505\n", ["timing.heartbeat_period"]),
        ("[timing]\ncontrol_perod = 0.004\n", ["control_perod"]),
        ("[vacuum]\nnode_id = 3\n", ["unique", "3"]),
        ("[vacuum]\nnode_id = 200\n", ["vacuum.node_id", "200"]),
        ("[master]\nnode_id = 16\n", ["unique", "master.node_id", "16"]),
        ("[master]\nnode_id = 0\n", ["master.node_id", "0"]),
        ("[timing]\nheartbeat_period = 30.0\nheartbeat_timeout_factor = 3.0\n", ["65.535 s", "master"]),
        ("[timing]\nheartbeat_timeout_factor = 2.0\n", ["timing.heartbeat_timeout_factor", "2.5", "lost heartbeat"]),
        ('[drives]\neds = "nope.eds"\n', ["drives.eds", "nope.eds"]),
        ("[drives]\nquick_stop_option = 3\n", ["quick_stop_option"]),
        ("[[joints]]\ndirection = 2\n" + "[[joints]]\n" * 5, ["joints (node 3).direction"]),
        ("[[joints]]\nnode_id = 3\n" * 6, ["joints[0].node_id", "can_nodes", "ur5.toml"]),
        ("[[joints]]\n" * 5, ["joints: 5 drives configured", "ur5 has 6 joints"]),
        ('[timing]\nboot_timeout = "long"\n', ["timing.boot_timeout", "'long'"]),
        ("[timing]\nboot_timeout = nan\n", ["timing.boot_timeout", "nan"]),
        ("[timing]\nenable_timeout = inf\n", ["timing.enable_timeout", "inf"]),
        ("[bus]\noptions = { recieve_own_messages = true }\n", ["bus.options", "recieve_own_messages", "virtual"]),
        ("[bus]\noptions = { rx_queue_size = nan }\n", ["bus.options: 'rx_queue_size' = nan"]),
        ("[[joints]]\n" + "[[joints]]\ngear_ratio = 0.0\n" + "[[joints]]\n" * 4, ["joints (node 4).gear_ratio"]),
    ],
)
def test_bad_values_name_the_key_and_the_file(tmp_path, toml, words):
    path = tmp_path / "bus.toml"
    path.write_text(toml)
    with pytest.raises(ConfigError) as info:
        load_cobot_bus_config(path)
    message = str(info.value)
    assert str(path) in message
    for word in words:
        assert word in message


def test_limit_overrides_may_only_tighten(robot):
    tighter = replace(CobotBusConfig(), limits=LimitOverrides(v_max=tuple(robot.v_max * 0.5)))
    np.testing.assert_allclose(resolve_limits(tighter, robot).v_max, robot.v_max * 0.5)
    looser = replace(CobotBusConfig(), limits=LimitOverrides(q_upper=tuple(robot.q_upper + 0.1)))
    with pytest.raises(ConfigError, match="only tighten"):
        resolve_limits(looser, robot)


def test_joint_count_and_int32_range_are_checked(robot):
    five = replace(CobotBusConfig(), joints=CobotBusConfig().joints[:5])
    with pytest.raises(ConfigError, match="5 drives"):
        resolve_limits(five, robot)
    huge = tuple(JointDriveConfig(node_id=n, gear_ratio=1e5) for n in range(3, 9))
    with pytest.raises(ConfigError, match="int32"):
        resolve_limits(replace(CobotBusConfig(), joints=huge), robot)


def test_direct_construction_validates_too():
    with pytest.raises(ConfigError, match=r"bus.interface"):
        BusConfig(interface="nonsense")
    with pytest.raises(ConfigError, match="realtime_priority"):
        TimingConfig(realtime_priority=120)


@pytest.mark.parametrize("direction, offset", [(1, 0.0), (-1, 0.3)])
def test_counts_radians_round_trip(direction, offset):
    conv = JointConversion.from_config(JointDriveConfig(node_id=3, direction=direction, offset=offset))
    assert conv.counts_per_rad == pytest.approx(131072 * 101 / (2 * np.pi))
    for q in (-2.5, 0.0, 1.234567):
        assert conv.to_rad(conv.to_counts(q)) == pytest.approx(q, abs=1.0 / conv.counts_per_rad)
    assert np.sign(conv.to_counts(offset + 0.1)) == direction
    assert conv.to_counts(offset) == 0
    assert conv.velocity_to_rad(conv.velocity_to_counts(1.5)) == pytest.approx(1.5, abs=1e-6)


@pytest.mark.parametrize(
    "section, key, value",
    [
        (section, key, value)
        for section, key in [
            ("timing", "boot_timeout"),
            ("timing", "enable_timeout"),
            ("timing", "sdo_timeout"),
            ("timing", "heartbeat_timeout_factor"),
            ("timing", "heartbeat_period"),
            ("timing", "control_period"),
            ("drives", "following_error_window"),
            ("drives", "quick_stop_deceleration"),
        ]
        for value in ("nan", "inf", "-inf", "-1.0", "1e9")
    ]
    + [
        ("timing", key, value)
        for key in ("max_missed_feedback", "setpoint_queue_depth")
        for value in ("0", "-3", "100000")
    ],
)
def test_timing_values_that_arm_safety_must_be_finite_and_in_range(tmp_path, section, key, value):
    """NaN or inf would switch a supervision off (a time-out that never expires) or crash it later."""
    path = tmp_path / "bus.toml"
    path.write_text(f"[{section}]\n{key} = {value}\n")
    with pytest.raises(ConfigError) as info:
        load_cobot_bus_config(path)
    message = str(info.value)
    assert str(path) in message and f"{section}.{key}" in message


def test_default_bus_config_describes_the_default_arm():
    """The repo's bus config and the default kinematics are the same arm: one drive per UR5 joint at the node
    of the arm file's map, and the comment after each [[joints]] names that joint and node in order."""
    import re

    from mrguide.robot import load_robot

    arm = load_robot()
    assert arm.name == "ur5"
    config = load_cobot_bus_config(REPO_TOML, arm)
    assert tuple(j.node_id for j in config.joints) == arm.node_ids
    assert len(config.joints) == arm.dof
    comments = re.findall(r"^\[\[joints\]\]\s*#\s*(\w+), node (\d+)$", REPO_TOML.read_text(), re.MULTILINE)
    assert [(name, int(node)) for name, node in comments] == list(zip(arm.joint_names, arm.node_ids))


def test_bus_drives_take_the_node_ids_of_the_arm_file(tmp_path):
    from mrguide.robot import RobotConfig, load_robot, shipped_arms

    text = shipped_arms()["ur10"].read_text()
    arm_file = tmp_path / "ur10-other-nodes.toml"
    arm_file.write_text(text.replace("shoulder_pan_joint = 3", "shoulder_pan_joint = 20"))
    arm = load_robot(RobotConfig(file=str(arm_file)))
    config = load_cobot_bus_config(REPO_TOML, arm)
    assert [j.node_id for j in config.joints] == [20, 4, 5, 6, 7, 8]
    np.testing.assert_array_equal(resolve_limits(config, arm).q_upper, arm.q_upper)  # the UR10's elbow: 3.1
