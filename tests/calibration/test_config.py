"""The shipped calibration config documents every key and loads; bad values are named."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from mrguide.calibration.config import CalibrationConfig, load_calibration_config
from mrguide.config import ConfigError, load_section
from mrguide.twin.markers import TwinCalibrationConfig
from tests.config_keys import undocumented

CONFIG = Path(__file__).parents[2] / "configs" / "devices" / "calibration.toml"


def test_shipped_config_documents_every_setting_and_loads():
    """A setting added to the code but not to the shipped file (the reference users copy) fails here."""
    text = CONFIG.read_text()
    assert undocumented(CalibrationConfig, "calibration.", text) == set()
    assert undocumented(TwinCalibrationConfig, "calibration_twin.", text) == set()
    load_calibration_config(CONFIG)
    load_section(TwinCalibrationConfig, CONFIG, "calibration_twin")


@pytest.mark.parametrize(
    "body, message",
    [
        ('[calibration.detector]\ncorner_refinement = "magic"\n', "corner_refinement must be one of"),
        ("[calibration.board]\nkind = 'charuco'\nsquare_size_m = 0.04\n", "must exceed marker_size_m"),
        ("[calibration.targets]\nboard_touched_corners = [[0, 0, 0], [1, 0, 0]]\n", "3 or 4 points"),
        ("[calibration.registration]\nmin_frame = 2\n", "min_frame"),
        ("[calibration.hmd]\ntracking_noise_m = 1.0\n", "calibration.hmd.tracking_noise_m = 1.0"),
        ("[calibration.hmd]\nseed = -1\n", "calibration.hmd.seed = -1"),
        (
            "[calibration.targets]\nmarkers = [{ id = -2, xyz = [0.4, 0.0, 0.0] }]\n",
            "calibration.targets.markers.id = -2",
        ),
        ("[calibration.board]\nrows = 1000\n", "calibration.board.rows = 1000"),
        ("[calibration.detector]\ncorner_window_px = 0\n", "calibration.detector.corner_window_px = 0"),
        ("[calibration_twin.intrinsics]\nwidth = 0\n", "intrinsics.width = 0"),
        ("[calibration_twin.intrinsics]\nfx = -1.0\n", "intrinsics.fx = -1.0"),
        ("[calibration_twin]\nsupersample = 9\n", "calibration_twin.supersample = 9"),
    ],
)
def test_bad_config_values(tmp_path, body, message):
    path = tmp_path / "c.toml"
    path.write_text(body)
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_calibration_config(path)
        load_section(TwinCalibrationConfig, path, "calibration_twin")
