"""The shipped calibration config matches the code defaults; bad values are named."""

from __future__ import annotations

from pathlib import Path

import pytest

from mrguide.calibration.config import CalibrationConfig, load_calibration_config
from mrguide.config import ConfigError, load_section
from mrguide.twin.markers import TwinCalibrationConfig

CONFIG = Path(__file__).parents[2] / "configs" / "calibration.toml"


def test_shipped_config_is_the_defaults():
    assert load_calibration_config(CONFIG) == CalibrationConfig()
    assert load_section(TwinCalibrationConfig, CONFIG, "calibration_twin") == TwinCalibrationConfig()


@pytest.mark.parametrize("body, message", [
    ('[calibration.detector]\ncorner_refinement = "magic"\n', "corner_refinement must be one of"),
    ("[calibration.board]\nkind = 'charuco'\nsquare_size_m = 0.04\n", "must exceed marker_size_m"),
    ("[calibration.targets]\nboard_touched_corners = [[0, 0, 0], [1, 0, 0]]\n", "3 or 4 points"),
    ("[calibration.registration]\nmin_frame = 2\n", "min_frame"),
])
def test_bad_config_values(tmp_path, body, message):
    path = tmp_path / "c.toml"
    path.write_text(body)
    with pytest.raises(ConfigError, match=message):
        load_calibration_config(path)
