"""The files shipped under configs/, by kind. Each list is loaded by the tests named beside it, and
tests/test_shipped_configs.py fails on a file under configs/ that is in none of them: a new shipped file needs a
kind (a folder below, or an entry in a list of device files) and so a test that loads it."""

from __future__ import annotations

from pathlib import Path

CONFIGS = Path(__file__).resolve().parents[1] / "configs"

#: Training run configs (configs/runs, and configs/parts: the cell with another part): tests/policies/
#: test_shipped_train_configs.py, tests/test_config_sections.py.
RUN_CONFIGS = sorted((CONFIGS / "runs").glob("*.toml")) + sorted((CONFIGS / "parts").glob("*.toml"))
#: Cells for deploy and sim-to-real: tests/test_config_sections.py, and the files they name in
#: tests/test_shipped_configs.py.
CELL_CONFIGS = sorted((CONFIGS / "cells").glob("*.toml"))
#: `mrguide experiment` files: tests/experiments/test_shipped_experiment_files.py.
EXPERIMENT_FILES = sorted((CONFIGS / "experiments").glob("*.toml"))
#: Devices, each kind with its loader in tests/test_shipped_configs.py: CAN bus descriptions ...
BUS_CONFIGS = [CONFIGS / "devices" / "cobot_bus.toml"]
#: ... `[calibration]` configs (also tests/calibration/test_config.py, tests/test_config_sections.py) ...
CALIBRATION_CONFIGS = [CONFIGS / "devices" / "calibration.toml"]
#: ... and calibration files written by `mrguide calibrate`.
CALIBRATION_FILES = [CONFIGS / "devices" / "camera_calibration.json"]

ALL = RUN_CONFIGS + CELL_CONFIGS + EXPERIMENT_FILES + BUS_CONFIGS + CALIBRATION_CONFIGS + CALIBRATION_FILES
