"""The shipped configs are found from any directory, a plain (non-editable) wheel carries them, every file under
configs/ is of a kind some test loads, and the files a shipped config names exist and load."""

from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from mrguide import shipped_configs
from mrguide.calibration.calibration_file import load_calibration
from mrguide.calibration.config import load_calibration_config
from mrguide.config import ConfigError, load_section
from mrguide.deploy.camera import load_marker_pipeline
from mrguide.deploy.session import DeployConfig
from mrguide.drivers.config import load_cobot_bus_config
from mrguide.robot import RobotConfig, load_robot, load_robot_config, shipped_arms
from mrguide.twin.markers import TwinCalibrationConfig
from tests import shipped_files

ROOT = Path(__file__).resolve().parents[1]


def test_the_installed_copy_is_used_when_there_is_no_checkout(tmp_path, monkeypatch):
    installed = tmp_path / "share" / "mrguide" / "configs"
    (installed / "experiments").mkdir(parents=True)
    (installed / "experiments" / "x.toml").write_text("[experiment]\n")
    monkeypatch.setattr(shipped_configs, "CHECKOUT", tmp_path / "no-checkout")
    monkeypatch.setattr(shipped_configs, "INSTALLED", installed)
    assert shipped_configs.shipped_config("experiments", "x.toml") == installed / "experiments" / "x.toml"
    with pytest.raises(ConfigError, match=r"cells/real_cell.toml is missing"):
        shipped_configs.shipped_config("cells", "real_cell.toml")


def test_defaults_resolve_outside_the_checkout(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert shipped_configs.shipped_config("cells", "real_cell.toml") == ROOT / "configs" / "cells" / "real_cell.toml"


def test_a_plain_wheel_carries_the_configs_and_the_arm_files(tmp_path):
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(tmp_path),
            str(ROOT),
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    (wheel,) = tmp_path.glob("mrguide-*.whl")
    names = set(zipfile.ZipFile(wheel).namelist())
    data = next(n.split("/data/")[0] for n in names if ".data/data/" in n) + "/data/share/mrguide/configs/"
    shipped = {
        str(p.relative_to(ROOT / "configs")) for p in (ROOT / "configs").rglob("*") if p.suffix in (".toml", ".json")
    }
    assert {data + s for s in shipped} <= names
    assert {"mrguide/arms/ur5.toml", "mrguide/arms/ur10.toml"} <= names


def test_every_file_under_configs_is_of_a_kind_that_a_test_loads():
    """A new file in configs/ must join a list of tests/shipped_files.py (and so the tests that load that list)."""
    on_disk = {p for p in (ROOT / "configs").rglob("*") if p.is_file()}
    listed = set(shipped_files.ALL)
    assert on_disk - listed == set(), "shipped files of no known kind: add them to tests/shipped_files.py"
    assert listed - on_disk == set(), "tests/shipped_files.py lists files that are not shipped"
    assert shipped_files.RUN_CONFIGS and shipped_files.CELL_CONFIGS and shipped_files.EXPERIMENT_FILES


@pytest.mark.parametrize("arm", sorted(shipped_arms()))
@pytest.mark.parametrize("path", shipped_files.BUS_CONFIGS, ids=lambda p: p.name)
def test_each_shipped_bus_config_loads_for_each_shipped_arm(path, arm):
    config = load_cobot_bus_config(path, load_robot(RobotConfig(name=arm)))
    assert len(config.joints) == load_robot(RobotConfig(name=arm)).dof


@pytest.mark.parametrize("path", shipped_files.CALIBRATION_CONFIGS, ids=lambda p: p.name)
def test_each_shipped_calibration_config_loads(path):
    load_calibration_config(path)
    load_section(TwinCalibrationConfig, path, "calibration_twin")


@pytest.mark.parametrize("path", shipped_files.CALIBRATION_FILES, ids=lambda p: p.name)
def test_each_shipped_calibration_file_loads(path):
    assert load_calibration(path).T_base_hmd.shape == (4, 4)


@pytest.mark.parametrize(
    "path", shipped_files.RUN_CONFIGS + shipped_files.CELL_CONFIGS, ids=lambda p: f"{p.parent.name}/{p.name}"
)
def test_the_files_a_shipped_config_names_are_there_and_load(path):
    """`[deploy] bus_config` and `[deploy.camera] calibration` are relative to the config: moving a file breaks them."""
    deploy = load_section(DeployConfig, path, "deploy")
    if deploy.bus_config:
        bus = path.parent / deploy.bus_config
        assert bus.resolve().is_relative_to(ROOT / "configs"), "a shipped config names a file outside configs/"
        load_cobot_bus_config(bus, load_robot(load_robot_config(path)))
    if deploy.pose_source == "camera":
        load_marker_pipeline(deploy.camera, path.parent)
