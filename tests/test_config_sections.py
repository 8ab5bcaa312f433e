"""Run configs: every known section is read by some command, an unknown one (a typo) is refused."""

from __future__ import annotations

from pathlib import Path

import pytest

from mrguide.calibration.config import load_calibration_config
from mrguide.cell.config import CellConfig
from mrguide.config import RUN_SECTIONS, ConfigError, load_section
from mrguide.deploy.safety import SafetyConfig
from mrguide.deploy.session import DeployConfig
from mrguide.policies.train_config import RunConfig
from mrguide.twin.markers import TwinCalibrationConfig
from tests import shipped_files

ROOT = Path(__file__).resolve().parents[1]


def _every_loader(path: Path) -> None:
    """What the commands read from a run config: train (robot, twin, task, train, the learners', guidance), deploy and
    sim2real (deploy, safety, plant), calibrate (calibration, calibration_twin)."""
    RunConfig.load(path)
    CellConfig.load(path)
    load_section(DeployConfig, path, "deploy")
    load_section(SafetyConfig, path, "safety")
    load_calibration_config(path)
    load_section(TwinCalibrationConfig, path, "calibration_twin")


@pytest.mark.parametrize("section", RUN_SECTIONS)
def test_every_known_section_is_read_by_a_command(tmp_path, section):
    """A key nobody reads in a known section is refused: the section is not a name on a list only."""
    path = tmp_path / "run.toml"
    path.write_text(f"[{section}]\nno_such_key = 1\n")
    with pytest.raises(ConfigError, match="no_such_key"):
        _every_loader(path)


def test_a_misspelt_section_is_refused_not_ignored(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text("[deploy]\nepisodes = 3\n\n[saftey]\nfollowing_error = 0.01\n")
    with pytest.raises(ConfigError, match=r"run.toml: unknown section \[saftey\]; this file may hold .*\[safety\]"):
        load_section(DeployConfig, path, "deploy")


def test_an_experiment_file_holds_only_its_experiment(tmp_path, run_cli):
    path = tmp_path / "exp.toml"
    path.write_text("[experiment]\nseeds = 2\n\n[train]\ntotal_steps = 10\n")
    result = run_cli(["experiment", "report", "noise-robustness", "--config", path, "--out", tmp_path / "out"])
    assert result.code == 2 and "exp.toml: unknown section [train]; this file may hold [experiment]" in result.err


@pytest.mark.parametrize(
    "path",
    shipped_files.RUN_CONFIGS + shipped_files.CELL_CONFIGS + shipped_files.CALIBRATION_CONFIGS,
    ids=lambda p: f"{p.parent.name}/{p.name}",
)
def test_shipped_run_configs_load_in_every_command(path):
    _every_loader(path)
