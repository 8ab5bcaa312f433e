"""Robot-world/hand-eye calibration with a marker carried by the robot."""

from __future__ import annotations

import cv2
import numpy as np
import pybullet as pb
import pytest

from mrguide.calibration import hand_eye
from mrguide.calibration.calibration_file import load_calibration, save_calibration
from mrguide.calibration.config import DetectorConfig
from mrguide.calibration.detection import MarkerDetector
from mrguide.calibration.errors import CalibrationError, NotEnoughMarkersError
from mrguide.calibration.pose import estimate_marker_pose
from mrguide.calibration.se3 import (
    apply,
    gaussian_noise,
    invert,
    make_T,
    rotation_about,
    rotation_angle_deg,
    rotation_from_rpy_deg,
)
from mrguide.twin.camera import look_at
from mrguide.twin.markers import TwinHmd, add_marker_plane

T_BASE_HMD = make_T(rotation_from_rpy_deg(90, 0, 160), [1.3, 0.4, 0.45])
T_TCP_MARKER = make_T(rotation_about([0, 0, 1], 0.4), [0.01, -0.02, 0.03])


def _tool_poses(n: int, rng: np.random.Generator) -> list[np.ndarray]:
    """TCP poses over the workspace, tool pointing roughly at the HMD, tilted about varied axes."""
    poses = []
    for _ in range(n):
        R = rotation_from_rpy_deg(*rng.uniform([-35, -35, -60], [35, 35, 60])) @ rotation_from_rpy_deg(0, 60, 0)
        poses.append(make_T(R, rng.uniform([0.35, -0.1, 0.15], [0.6, 0.3, 0.35])))
    return poses


@pytest.mark.parametrize("noise", [0.0, 0.0005])
def test_numpy_solver_recovers_both_transforms(noise):
    rng = np.random.default_rng(1)
    A = _tool_poses(12, rng)
    B = [invert(T_BASE_HMD) @ a @ T_TCP_MARKER @ gaussian_noise(rng, noise, 10 * noise) for a in A]
    X, Z = hand_eye._shah(A, B)
    assert np.linalg.norm(Z[:3, 3] - T_BASE_HMD[:3, 3]) < 1e-9 + 10 * noise
    assert rotation_angle_deg(Z[:3, :3], T_BASE_HMD[:3, :3]) < 1e-6 + 100 * noise
    assert np.linalg.norm(X[:3, 3] - T_TCP_MARKER[:3, 3]) < 1e-9 + 10 * noise


def test_hand_eye_refuses_too_few_or_degenerate_poses():
    A = [make_T(np.eye(3), [0.4 + 0.05 * i, 0.0, 0.2]) for i in range(4)]  # translations only
    B = [invert(T_BASE_HMD) @ a @ T_TCP_MARKER for a in A]
    with pytest.raises(NotEnoughMarkersError, match="at least 3"):
        hand_eye.solve_robot_world_hand_eye(A[:2], B[:2])
    with pytest.raises(CalibrationError, match="two different axes"):
        hand_eye._shah(A, B)


@pytest.mark.skipif(
    not hasattr(cv2, "calibrateRobotWorldHandEye"), reason="this cv2 build lacks the binding (opencv#29565)"
)
def test_opencv_and_numpy_solvers_agree():
    rng = np.random.default_rng(2)
    A = _tool_poses(10, rng)
    B = [invert(T_BASE_HMD) @ a @ T_TCP_MARKER @ gaussian_noise(rng, 0.0005, 0.05) for a in A]
    (X1, Z1), (X2, Z2) = hand_eye._opencv(A, B), hand_eye._shah(A, B)
    assert np.linalg.norm(Z1[:3, 3] - Z2[:3, 3]) < 0.002 and rotation_angle_deg(Z1[:3, :3], Z2[:3, :3]) < 0.2
    assert np.linalg.norm(X1[:3, 3] - X2[:3, 3]) < 0.002 and rotation_angle_deg(X1[:3, :3], X2[:3, :3]) < 0.2


def test_hand_eye_from_twin_renders(client, hl2, tmp_path):
    """An 8 cm marker on the tool, seen by the HMD camera at 12 robot poses: a workspace point maps within
    3 mm, the rotation within 0.3 deg (single-marker orientation noise of ~0.2 deg limits it)."""
    rng = np.random.default_rng(4)
    cam_eye, cam_target = np.array([1.0, 0.1, 0.6]), np.array([0.47, 0.1, 0.25])
    hmd = TwinHmd(client, T_BASE_HMD, look_at(cam_eye, cam_target, np.array([0, 0, 1.0])))
    detector = MarkerDetector(DetectorConfig(marker_size_m=0.08))
    A, B = [], []
    for T_base_tcp in _tool_poses(12, rng):
        body = add_marker_plane(client, "DICT_4X4_50", 3, 0.08, T_base_tcp @ T_TCP_MARKER)
        frame = hmd.frame()
        pb.removeBody(body, physicsClientId=client)
        corners = detector.detect(frame.image, camera=hl2).corners_of(3)
        if corners is None:
            continue
        pose = estimate_marker_pose(corners, 0.08, hl2)
        A.append(T_base_tcp)
        B.append(frame.T_hmd_cam @ pose.T_cam_target)
    assert len(A) >= 10
    res = hand_eye.solve_robot_world_hand_eye(A, B)
    centre = np.array([0.475, 0.1, 0.0])  # where it matters: a workspace point seen through the calibration
    assert np.linalg.norm(apply(res.T_base_hmd @ invert(T_BASE_HMD), centre) - centre) < 0.003
    assert rotation_angle_deg(res.T_base_hmd[:3, :3], T_BASE_HMD[:3, :3]) < 0.3
    assert res.max_m < 0.004
    saved = load_calibration(save_calibration(res.record("DICT_4X4_50", 0.08, hl2.to_dict()), tmp_path / "he.json"))
    assert saved.method == "hand-eye" and np.allclose(saved.extra["T_tcp_marker"], res.T_tcp_marker)
