"""`mrguide calibrate` with bad input: one line on stderr naming what and where, exit 2, and nothing written.

Output locations are checked before anything is computed (the calibration itself is replaced by a stub
that fails the test if it runs), and both files are written together or not at all.
"""

from __future__ import annotations

import errno
import json
import os

import cv2
import numpy as np
import pytest

from mrguide.calibration import commands
from mrguide.calibration.calibration_file import CalibrationRecord
from mrguide.calibration.procedure import CalibrationRun
from mrguide.twin import commands as twin_commands

GOOD_K = {"width": 1280, "height": 720, "fx": 1011.0, "fy": 1011.0, "cx": 639.5, "cy": 359.5}
CORRUPT_YAML = "%YAML:1.0\n---\nimage_width: [1, 2\ncamera_matrix: !!opencv-matrix\n  rows: 3\n"


@pytest.fixture
def files(tmp_path):
    """An image folder (one blank 1280x720 image) and a file that is in the way of output paths."""
    (tmp_path / "images").mkdir()
    cv2.imwrite(str(tmp_path / "images" / "a.png"), np.full((720, 1280, 3), 180, np.uint8))
    (tmp_path / "afile").write_text("not a directory")
    return tmp_path


@pytest.fixture
def no_calibration(monkeypatch):
    """Fail the test if a calibration is computed (from images or in the twin)."""
    import mrguide.calibration.procedure
    import mrguide.twin.markers

    def computed(*args, **kwargs):
        raise AssertionError("the calibration ran before the input was refused")

    monkeypatch.setattr(mrguide.calibration.procedure, "calibrate_frames", computed)  # run_calibrate imports it
    monkeypatch.setattr(mrguide.twin.markers, "calibrate_twin_hmd", computed)


def _intrinsics(path, text: str):
    path.write_text(text)
    return path


CASES = [
    # (id, argv after "calibrate" given the tmp dir, words in the one stderr line)
    (
        "width Infinity",
        lambda d: [
            "--images",
            d / "images",
            "--intrinsics",
            _intrinsics(d / "k.json", json.dumps({**GOOD_K, "width": float("inf")})),
        ],
        ["k.json", "width = inf", "whole number of pixels"],
    ),
    (
        "width 640.5",
        lambda d: [
            "--images",
            d / "images",
            "--intrinsics",
            _intrinsics(d / "k.json", json.dumps({**GOOD_K, "width": 640.5})),
        ],
        ["k.json", "width = 640.5"],
    ),
    (
        "TOML width inf",
        lambda d: [
            "--images",
            d / "images",
            "--intrinsics",
            _intrinsics(d / "k.toml", "width = inf\nheight = 720\nfx = 1.0\nfy = 1.0\ncx = 0.0\ncy = 0.0\n"),
        ],
        ["k.toml", "width = inf"],
    ),
    (
        "fx nan",
        lambda d: [
            "--images",
            d / "images",
            "--intrinsics",
            _intrinsics(d / "k.json", json.dumps({**GOOD_K, "fx": float("nan")})),
        ],
        ["k.json", "non-finite"],
    ),
    (
        "corrupt YAML",
        lambda d: ["--images", d / "images", "--intrinsics", _intrinsics(d / "k.yaml", CORRUPT_YAML)],
        ["k.yaml", "cannot parse intrinsics", "Parsing error"],
    ),
    (
        "--out under a file",
        lambda d: ["--twin", "--out", d / "afile" / "cal.json", "--overlay", d / "o.png"],
        ["--out", "afile", "is not a directory"],
    ),
    (
        "--out is a directory",
        lambda d: ["--twin", "--out", d / "images", "--overlay", d / "o.png"],
        ["--out", "images", "not a regular file"],
    ),
    (
        "--overlay under a file",
        lambda d: ["--twin", "--out", d / "cal.json", "--overlay", d / "afile" / "o.png"],
        ["--overlay", "afile", "is not a directory"],
    ),
    (
        "--overlay not an image type",
        lambda d: ["--twin", "--out", d / "cal.json", "--overlay", d / "o.txt"],
        ["--overlay", "o.txt", "'.txt'"],
    ),
    (
        "--overlay /dev/full",
        lambda d: ["--twin", "--out", d / "cal.json", "--overlay", "/dev/full"],
        ["--overlay", "/dev/full", "not a regular file"],
    ),
    (
        "--out = --overlay",
        lambda d: ["--twin", "--out", d / "x.png", "--overlay", d / "x.png"],
        ["--out and --overlay are the same file"],
    ),
    (
        "config marker size nan",
        lambda d: [
            "--twin",
            "--out",
            d / "cal.json",
            "--overlay",
            d / "o.png",
            "--config",
            _intrinsics(d / "c.toml", "[calibration.detector]\nmarker_size_m = nan\n"),
        ],
        ["c.toml", "[calibration]: detector.marker_size_m = nan"],
    ),
    (
        "config board columns 0",
        lambda d: [
            "--twin",
            "--out",
            d / "cal.json",
            "--overlay",
            d / "o.png",
            "--config",
            _intrinsics(d / "c.toml", "[calibration.board]\ncolumns = 0\n"),
        ],
        ["c.toml", "calibration.board.columns = 0"],
    ),
    (
        "twin supersample 100",
        lambda d: [
            "--twin",
            "--out",
            d / "cal.json",
            "--overlay",
            d / "o.png",
            "--config",
            _intrinsics(d / "c.toml", "[calibration_twin]\nsupersample = 100\n"),
        ],
        ["c.toml", "calibration_twin.supersample = 100"],
    ),
]


@pytest.mark.parametrize("make_argv, words", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_refused_before_anything_is_computed_or_written(files, run_cli, no_calibration, make_argv, words):
    argv = make_argv(files)
    before = sorted(files.rglob("*"))
    run_cli(["calibrate", *argv]).assert_refused(*words)
    assert sorted(files.rglob("*")) == before


def test_a_failed_write_leaves_neither_file(files, run_cli, monkeypatch):
    """The overlay's write fails after the calibration file's: neither is left, nor any temporary file."""
    record = CalibrationRecord(np.eye(4), "DICT_4X4_50", 0.04, "board", 0.001, 0.002, 1, 80)
    run = CalibrationRun(record, None, (), (np.zeros((72, 128, 3), np.uint8),))
    monkeypatch.setattr(twin_commands, "run_twin_calibration", lambda config, cfg: (run, None))
    monkeypatch.setattr(commands, "_report", lambda run, truth: None)
    real_fsync, calls = os.fsync, []

    def fsync(fd):
        calls.append(fd)
        if len(calls) == 2:
            raise OSError(errno.ENOSPC, "No space left on device")
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", fsync)
    result = run_cli(["calibrate", "--twin", "--out", files / "cal.json", "--overlay", files / "o.png"])
    assert result.code == 1 and "No space left on device" in result.err and len(result.err.splitlines()) == 1
    assert len(calls) == 2
    assert sorted(p.name for p in files.iterdir()) == ["afile", "images"]
    monkeypatch.setattr(os, "fsync", real_fsync)
    assert run_cli(["calibrate", "--twin", "--out", files / "cal.json", "--overlay", files / "o.png"]).code == 0
    assert json.loads((files / "cal.json").read_text())["n_points"] == 80
    assert cv2.imread(str(files / "o.png")).shape == (72, 128, 3)
