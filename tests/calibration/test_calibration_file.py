"""Calibration file: round trip, and one clear error per kind of bad file."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

from mrguide.calibration.calibration_file import CalibrationRecord, load_calibration, save_calibration
from mrguide.calibration.errors import CalibrationFileError
from mrguide.calibration.se3 import make_T, rotation_about

RECORD = CalibrationRecord(
    T_base_hmd=make_T(rotation_about([1, 2, 3], 0.7), [1.3, 0.4, 0.45]),
    dictionary="DICT_4X4_50",
    marker_size_m=0.04,
    method="board",
    rms_residual_m=0.0004,
    max_residual_m=0.0011,
    n_frames=4,
    n_points=320,
    camera={"width": 1280, "height": 720, "fx": 1011.0, "fy": 1011.0, "cx": 639.5, "cy": 359.5, "dist": []},
    extra={"frames_rejected": {"view3": "outlier"}},
)


def test_round_trip(tmp_path):
    path = save_calibration(RECORD, tmp_path / "sub" / "cal.json")
    back = load_calibration(path, expect_dictionary="4x4_50", expect_marker_size_m=0.04)
    assert np.array_equal(back.T_base_hmd, RECORD.T_base_hmd)
    for key in (
        "dictionary",
        "marker_size_m",
        "method",
        "rms_residual_m",
        "max_residual_m",
        "n_frames",
        "n_points",
        "created",
        "camera",
        "extra",
    ):
        assert getattr(back, key) == getattr(RECORD, key), key


def _write(tmp_path, mutate) -> str:
    data = RECORD.to_json()
    mutate(data)
    path = tmp_path / "cal.json"
    path.write_text(json.dumps(data))
    return str(path)


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda d: d.pop("format"), "not an mrguide calibration file"),
        (lambda d: d.update(version=2), "version 2"),
        (lambda d: d.pop("n_points"), "missing key 'n_points'"),
        (lambda d: d.update(T_base_hmd=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]), "not a rigid"),
        (lambda d: d.update(T_base_hmd=[[1, 2], [3, 4]]), "not a rigid"),
        (lambda d: d.update(T_base_hmd="eye"), "wrong type"),
        (lambda d: d.update(dictionary="DICT_9X9_7"), "unknown ArUco dictionary"),
        (lambda d: d.update(rms_residual_m=-1.0), "'rms_residual_m' = -1.0"),
        (lambda d: d.update(method="guess"), "unknown method"),
        (lambda d: d.update(n_frames=-3), "'n_frames' = -3"),
        (lambda d: d.update(n_frames=2.5), "'n_frames' has the wrong type"),
        (lambda d: d.update(n_frames=True), "'n_frames' has the wrong type"),
        (lambda d: d.update(n_points=2), "'n_points' = 2"),  # fewer points than frames
        (lambda d: d.update(marker_size_m=float("inf")), "'marker_size_m' = inf"),
        (lambda d: d.update(max_residual_m=float("nan")), "'max_residual_m' = nan"),
        (lambda d: d.update(rms_residual_m=0.002), "exceeds max_residual_m"),
        (lambda d: d["T_base_hmd"][0].__setitem__(3, float("nan")), "not a rigid"),
        (lambda d: d.update(created=5), "'created' has the wrong type"),
        (lambda d: d.update(camera={**d["camera"], "width": float("inf")}), "'camera': intrinsics width = inf"),
        (lambda d: d.update(camera=[1280, 720]), "'camera' must be an object"),
        (lambda d: d.update(board={"columns": -1}), "calibration.board.columns = -1"),
        (lambda d: d.update(extra="none"), "'extra' must be an object"),
        (lambda d: d.update(note="hand-edited"), "unknown keys ['note']"),
    ],
)
def test_bad_files_are_named_and_explained(tmp_path, mutate, message):
    path = _write(tmp_path, mutate)
    with pytest.raises(CalibrationFileError, match=re.escape(message)) as err:
        load_calibration(path)
    assert "cal.json" in str(err.value)


def test_corrupt_missing_and_mismatched_files(tmp_path):
    (tmp_path / "bad.json").write_text('{"format": "mrguide-calib')
    with pytest.raises(CalibrationFileError, match="not valid JSON"):
        load_calibration(tmp_path / "bad.json")
    with pytest.raises(CalibrationFileError, match="not found"):
        load_calibration(tmp_path / "nope.json")
    path = save_calibration(RECORD, tmp_path / "cal.json")
    with pytest.raises(CalibrationFileError, match="DICT_5X5_100"):
        load_calibration(path, expect_dictionary="DICT_5X5_100")
    with pytest.raises(CalibrationFileError, match=r"0.05 m"):
        load_calibration(path, expect_marker_size_m=0.05)
