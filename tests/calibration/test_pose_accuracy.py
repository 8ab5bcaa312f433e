"""Marker and board pose accuracy on clean renders from the HoloLens 2 PV camera (1280x720, f = 1011 px)."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.calibration.augment import occlude
from mrguide.calibration.boards import board_pose_on_table, make_board, marker_pose_on_table, single_marker_corners
from mrguide.calibration.config import BoardConfig, DetectorConfig
from mrguide.calibration.detection import MarkerDetector
from mrguide.calibration.errors import NotEnoughMarkersError
from mrguide.calibration.pose import BoardPoseEstimator, estimate_marker_pose
from mrguide.calibration.se3 import apply, invert, make_T, rotation_about, rotation_angle_deg
from mrguide.twin.camera import Camera
from mrguide.twin.markers import HOLOLENS2_PV, add_board, add_marker_plane, render

VIEWS = [(d, tilt, az) for d in (0.5, 0.75, 1.0) for tilt, az in ((0, 0), (25, 160), (50, 230))]


def _marker_errors(client, orbit, hl2, size):
    T_base_marker = marker_pose_on_table((0.5, 0.1, 0.0005), 20.0)
    add_marker_plane(client, "DICT_4X4_50", 5, size, T_base_marker)
    det = MarkerDetector(DetectorConfig(marker_size_m=size))
    pos, rot = [], []
    for d, tilt, az in VIEWS:
        cam = Camera(client, orbit([0.5, 0.1, 0.0], d, tilt, az), HOLOLENS2_PV)
        corners = det.detect(render(cam), camera=hl2).corners_of(5)
        assert corners is not None, (d, tilt)
        T_cam_base = invert(cam.T_base_cam)
        pose = estimate_marker_pose(corners, size, hl2, normal_hint_cam=T_cam_base[:3, 2])
        truth = T_cam_base @ T_base_marker
        pos.append(np.linalg.norm(pose.T_cam_target[:3, 3] - truth[:3, 3]))
        rot.append(rotation_angle_deg(pose.T_cam_target[:3, :3], truth[:3, :3]))
    return np.array(pos), np.array(rot)


def test_calibration_marker_within_2mm_and_1deg(client, orbit, hl2):
    """6 cm marker, 0.5-1.0 m, 0-50 deg off the normal."""
    pos, rot = _marker_errors(client, orbit, hl2, 0.06)
    assert pos.max() <= 0.002 and rot.max() <= 1.0, (pos, rot)


def test_object_marker_within_3mm_and_2deg(client, orbit, hl2):
    """4 cm marker (the largest that fits a 5 cm cube with a quiet zone): looser, as stated in the docs."""
    pos, rot = _marker_errors(client, orbit, hl2, 0.04)
    assert pos.max() <= 0.003 and rot.max() <= 2.0, (pos, rot)


def test_head_on_marker_at_principal_point(hl2):
    """IPPE returns a wrong, plane-flipped pose for a marker exactly head-on at the image centre; SQPnP covers it."""
    T = make_T(rotation_about([1, 0, 0], np.pi) @ rotation_about([0, 0, 1], 0.3), [0.0, 0.0, 1.0])
    uv = hl2.project(apply(T, single_marker_corners(0.06))) + np.array([[0.01, 0], [0, -0.01], [-0.01, 0], [0, 0.01]])
    pose = estimate_marker_pose(uv, 0.06, hl2)
    assert pose.reprojection_error_px < 0.05
    assert rotation_angle_deg(pose.T_cam_target[:3, :3], T[:3, :3]) < 2.0


def test_ambiguity_flag_and_prior(hl2):
    """A small, far marker under corner noise: without a prior the flip is flagged; the prior picks the right
    branch more often than the lowest reprojection error does."""
    R = rotation_about([1, 0, 0], np.radians(200))  # facing the camera, tilted 20 deg
    T = make_T(R, [0.05, 0.02, 1.5])
    uv = hl2.project(apply(T, single_marker_corners(0.04)))
    rng = np.random.default_rng(0)
    flagged = wrong_plain = wrong_prior = 0
    for _ in range(100):
        noisy = uv + rng.normal(0.0, 0.3, uv.shape)
        plain = estimate_marker_pose(noisy, 0.04, hl2)
        prior = estimate_marker_pose(noisy, 0.04, hl2, normal_hint_cam=R[:, 2])
        flagged += plain.ambiguous
        wrong_plain += rotation_angle_deg(plain.T_cam_target[:3, :3], R) > 20
        wrong_prior += rotation_angle_deg(prior.T_cam_target[:3, :3], R) > 20
        assert not prior.ambiguous
    assert flagged > 30
    assert wrong_prior < 0.6 * wrong_plain


@pytest.mark.parametrize("kind", ["grid", "charuco"])
def test_board_pose_sub_millimetre(client, orbit, hl2, kind):
    """Measured at 0.7-1.0 m: grid 0.04 mm / 0.01 deg; ChArUco 0.2 mm (OpenCV 5.0) to 0.6 mm (4.12) / 0.07 deg,
    its chessboard corners being refined by OpenCV's cornerSubPix rather than by edge fits."""
    cfg = BoardConfig(kind=kind)
    det = MarkerDetector(DetectorConfig())
    board = make_board(cfg, det.dictionary)
    T_base_board = board_pose_on_table((0.33, 0.25, cfg.thickness_m), 10.0)
    add_board(client, board, T_base_board)
    estimator = BoardPoseEstimator(board, det, min_markers=4)
    centre = apply(T_base_board, np.r_[np.array(board.size_m) / 2, 0.0])
    for d, tilt, az in ((0.7, 30, 180), (1.0, 50, 120)):
        cam = Camera(client, orbit(centre, d, tilt, az), HOLOLENS2_PV)
        pose, used = estimator.estimate(render(cam), hl2)
        truth = invert(cam.T_base_cam) @ T_base_board
        assert len(used) == len(board.ids)
        assert np.linalg.norm(pose.T_cam_target[:3, 3] - truth[:3, 3]) < 0.001
        assert rotation_angle_deg(pose.T_cam_target[:3, :3], truth[:3, :3]) < 0.1


def test_board_with_too_few_markers_is_refused(client, orbit, hl2):
    cfg = BoardConfig()
    det = MarkerDetector(DetectorConfig())
    board = make_board(cfg, det.dictionary)
    T_base_board = board_pose_on_table((0.33, 0.25, cfg.thickness_m), 0.0)
    add_board(client, board, T_base_board)
    cam = Camera(client, orbit(apply(T_base_board, [0.15, 0.12, 0.0]), 0.7, 30, 180), HOLOLENS2_PV)
    outline = cam.project(apply(T_base_board, board.outline()))
    image = occlude(render(cam), outline, 0.85)  # leaves one column of markers
    with pytest.raises(NotEnoughMarkersError, match=r"of the board's 20 markers visible .* at least 8 are required"):
        BoardPoseEstimator(board, det, min_markers=8).estimate(image, hl2)
