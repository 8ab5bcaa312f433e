"""`mrguide calibrate`: twin and image-folder modes, and one clear message per kind of bad input."""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from mrguide.calibration.calibration_file import load_calibration
from mrguide.calibration.se3 import invert, rotation_angle_deg
from mrguide.cli import main
from mrguide.twin.markers import TwinCalibrationConfig
from tests.conftest import render_calibration_images

TWIN = TwinCalibrationConfig()


def _run(argv: list[str]) -> int:
    return main(["calibrate", *argv])


@pytest.fixture
def image_folder(client, tmp_path):
    """Twin renders of the default board from the default views, saved as PNGs, with intrinsics and poses files."""
    return render_calibration_images(client, tmp_path)


def test_twin_mode_writes_file_and_overlay(tmp_path, capsys):
    out, png = tmp_path / "cal.json", tmp_path / "overlay.png"
    assert _run(["--twin", "--out", str(out), "--overlay", str(png)]) == 0
    text = capsys.readouterr().out
    assert "registration: 4 frames, 320 points" in text and "twin ground truth" in text
    record = load_calibration(out, expect_dictionary="DICT_4X4_50")
    assert np.linalg.norm(record.T_base_hmd[:3, 3] - TWIN.T_base_hmd[:3, 3]) < 0.002
    assert cv2.imread(str(png)) is not None


def test_images_mode_with_head_tracking_poses(image_folder, tmp_path, capsys):
    out = tmp_path / "cal.json"
    code = _run(
        [
            "--images",
            str(image_folder),
            "--intrinsics",
            str(tmp_path / "k.json"),
            "--poses",
            str(tmp_path / "poses.json"),
            "--out",
            str(out),
            "--overlay",
            str(tmp_path / "o.png"),
        ]
    )
    assert code == 0, capsys.readouterr().err
    record = load_calibration(out)
    assert record.rms_residual_m < 0.003 and record.n_frames == 3
    assert rotation_angle_deg(record.T_base_hmd[:3, :3], TWIN.T_base_hmd[:3, :3]) < 0.1
    assert np.linalg.norm((invert(TWIN.T_base_hmd) @ record.T_base_hmd)[:3, 3]) < 0.002


def test_bad_inputs_get_clear_messages(image_folder, tmp_path, capsys):
    k, poses, out = (
        tmp_path / "k.json",
        tmp_path / "poses.json",
        ["--out", str(tmp_path / "c.json"), "--overlay", str(tmp_path / "o.png")],
    )

    def fails(argv, message):
        assert _run(argv + out) == 2
        assert message in capsys.readouterr().err

    fails(["--images", str(image_folder)], "--images needs --intrinsics")
    (tmp_path / "dict.toml").write_text('[calibration.detector]\ndictionary = "DICT_4X4_77"\n')
    fails(
        ["--images", str(image_folder), "--intrinsics", str(k), "--config", str(tmp_path / "dict.toml")],
        "unknown ArUco dictionary 'DICT_4X4_77'",
    )
    (tmp_path / "small.json").write_text(
        json.dumps({"width": 640, "height": 480, "fx": 600, "fy": 600, "cx": 320, "cy": 240})
    )
    fails(
        ["--images", str(image_folder), "--intrinsics", str(tmp_path / "small.json")],
        "image is 1280x720 but the intrinsics are for 640x480",
    )
    fails(
        ["--images", str(image_folder), "--intrinsics", str(k), "--poses", str(tmp_path / "none.json")],
        "cannot read the head-tracking poses",
    )
    empty = tmp_path / "empty"
    empty.mkdir()
    cv2.imwrite(str(empty / "table.png"), np.full((720, 1280, 3), 180, np.uint8))
    fails(["--images", str(empty), "--intrinsics", str(k)], "table.png: 0 target markers usable, 4 required")
    (image_folder / "broken.png").write_bytes(b"not a png")
    fails(["--images", str(image_folder), "--intrinsics", str(k), "--poses", str(poses)], "no pose for broken.png")
    fails(["--images", str(image_folder), "--intrinsics", str(k)], "broken.png: cannot read the image")
