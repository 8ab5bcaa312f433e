"""Registration of the twin HMD to the robot base from rendered calibration targets."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from mrguide.calibration.boards import board_pose_on_table, make_board
from mrguide.calibration.config import (
    BoardConfig,
    CalibrationConfig,
    DetectorConfig,
    HmdNoiseConfig,
    MarkerPlacement,
    TargetsConfig,
)
from mrguide.calibration.detection import MarkerDetector
from mrguide.calibration.errors import CalibrationError, NotEnoughMarkersError
from mrguide.calibration.se3 import apply, invert, rotation_angle_deg
from mrguide.calibration.targets import board_pose_from_touched_corners
from mrguide.twin.camera import look_at
from mrguide.twin.markers import TwinCalibrationConfig, TwinHmd, calibrate_twin_hmd

TWIN = TwinCalibrationConfig()
CENTRE = np.array([0.475, 0.1, 0.0])


def _workspace_error(T_est: np.ndarray) -> float:
    """How far the estimate puts a workspace point seen by the HMD (m)."""
    return float(np.linalg.norm(apply(T_est @ invert(TWIN.T_base_hmd), CENTRE) - CENTRE))


def _hmd(client) -> TwinHmd:
    return TwinHmd(
        client, TWIN.T_base_hmd, look_at(np.array(TWIN.views[0]), np.array(TWIN.look_at), np.array([0, 0, 1.0]))
    )


def test_board_registration_residual_and_truth(client):
    run = calibrate_twin_hmd(_hmd(client), CalibrationConfig(), TWIN.views, TWIN.look_at)
    assert run.registration.rms_m <= 0.003 and run.registration.max_m <= 0.003
    assert len(run.registration.frames_used) == len(TWIN.views)
    assert _workspace_error(run.record.T_base_hmd) < 0.001
    assert rotation_angle_deg(run.record.T_base_hmd[:3, :3], TWIN.T_base_hmd[:3, :3]) < 0.1
    assert run.record.method == "board" and run.record.n_points == 4 * 20 * len(TWIN.views)


def test_board_registration_with_head_tracking_noise(client):
    """2 mm / 0.2 deg tracking noise per frame: residuals reflect it, the fit averages it down."""
    noise = HmdNoiseConfig(tracking_noise_m=0.002, tracking_noise_deg=0.2, seed=5)
    views = TWIN.views + ((0.9, 0.3, 0.65), (1.0, -0.05, 0.5))
    run = calibrate_twin_hmd(_hmd(client), CalibrationConfig(), views, TWIN.look_at, noise)
    assert 0.001 < run.registration.rms_m < 0.006
    assert _workspace_error(run.record.T_base_hmd) < 0.003


def test_single_markers_on_the_table(client):
    markers = (
        MarkerPlacement(0, (0.38, 0.0, 0.0005), 0.0),
        MarkerPlacement(1, (0.6, 0.05, 0.0005), 30.0),
        MarkerPlacement(2, (0.45, 0.3, 0.0005), -20.0),
        MarkerPlacement(3, (0.62, 0.28, 0.0005), 90.0),
    )
    cfg = CalibrationConfig(
        detector=DetectorConfig(marker_size_m=0.08), targets=TargetsConfig(use_board=False, markers=markers)
    )
    cfg = dataclasses.replace(cfg, registration=dataclasses.replace(cfg.registration, min_markers=3))
    run = calibrate_twin_hmd(_hmd(client), cfg, TWIN.views, TWIN.look_at)
    assert run.record.method == "markers"
    assert run.registration.rms_m <= 0.003
    assert _workspace_error(run.record.T_base_hmd) < 0.002


def test_too_few_markers_in_view_is_an_error_not_a_transform(client):
    """Looking past the board (only its edge in view) must not produce a calibration."""
    views = ((0.9, -0.45, 0.5), (0.95, -0.5, 0.6))
    with pytest.raises(NotEnoughMarkersError, match="usable frames, 1 required"):
        calibrate_twin_hmd(_hmd(client), CalibrationConfig(), views, (0.55, -0.45, 0.0))


def test_board_pose_from_touched_corners():
    board = make_board(BoardConfig(), MarkerDetector().dictionary)
    T = board_pose_on_table((0.33, 0.25, 0.003), 12.0)
    touched = apply(T, board.outline()) + np.random.default_rng(0).normal(0, 0.0005, (4, 3))
    T_est = board_pose_from_touched_corners(board, touched, tolerance_m=0.003)
    assert np.linalg.norm(T_est[:3, 3] - T[:3, 3]) < 0.002
    with pytest.raises(CalibrationError, match="corner order"):
        board_pose_from_touched_corners(board, touched[[1, 0, 2, 3]], tolerance_m=0.003)
