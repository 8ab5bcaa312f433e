"""Object pose sources through the HMD calibration, in the twin (sim-to-real condition 3)."""

from __future__ import annotations

import re

import numpy as np
import pybullet as pb
import pytest

from mrguide.calibration.calibration_file import CalibrationRecord
from mrguide.calibration.config import DetectorConfig, HmdNoiseConfig
from mrguide.calibration.detection import MarkerDetector
from mrguide.calibration.errors import CalibrationError
from mrguide.calibration.pose_sources import HmdAnnotationPoseSource, MarkerPoseSource
from mrguide.calibration.se3 import make_T, rotation_from_rpy_deg
from mrguide.pose_source import PoseUnavailable
from mrguide.twin.camera import look_at
from mrguide.twin.markers import MarkerOnBody, TwinHmd, annotations_of_body, hmd_marker_pose_source, marker_on_cube_top

T_BASE_HMD = make_T(rotation_from_rpy_deg(90, 0, 160), [1.3, 0.4, 0.45])
CUBE = 0.05
DETECTOR = DetectorConfig(marker_size_m=0.04)


@pytest.fixture
def cell(client):
    """A 5 cm cube on the table with a 4 cm marker (id 0) on its top face, and the HMD looking at it from ~0.75 m."""
    col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[CUBE / 2] * 3, physicsClientId=client)
    vis = pb.createVisualShape(
        pb.GEOM_BOX, halfExtents=[CUBE / 2] * 3, rgbaColor=[0.85, 0.1, 0.1, 1], physicsClientId=client
    )
    cube = pb.createMultiBody(0.2, col, vis, [0.5, -0.05, CUBE / 2], physicsClientId=client)
    marker = MarkerOnBody(client, cube, marker_on_cube_top(CUBE), "DICT_4X4_50", 0, 0.04, quiet_zone_m=0.005)
    hmd = TwinHmd(
        client,
        T_BASE_HMD,
        look_at(np.array([1.0, 0.1, 0.55]), np.array([0.5, -0.05, 0.05]), np.array([0, 0, 1.0])),
        attached=[marker],
    )
    return cube, hmd


def _move(client, cube, xy, yaw_deg=0.0):
    pb.resetBasePositionAndOrientation(
        cube, [xy[0], xy[1], CUBE / 2], pb.getQuaternionFromEuler([0, 0, np.radians(yaw_deg)]), physicsClientId=client
    )


def test_marker_pose_source_gives_object_centre(client, cell):
    cube, hmd = cell
    offset = -marker_on_cube_top(CUBE)[:3, 3]  # marker frame -> cube centre
    source = hmd_marker_pose_source(hmd, T_BASE_HMD, DETECTOR, 0, offset)
    for xy, yaw in (((0.5, -0.05), 0.0), ((0.42, 0.1), 35.0), ((0.6, 0.2), -60.0)):
        _move(client, cube, xy, yaw)
        assert np.linalg.norm(source.object_position() - [xy[0], xy[1], CUBE / 2]) < 0.003


def test_calibration_error_and_tracking_noise_show_up(client, cell):
    cube, hmd = cell
    offset = -marker_on_cube_top(CUBE)[:3, 3]
    _move(client, cube, (0.475, 0.1))  # at the pivot of the calibration error
    shifted = hmd_marker_pose_source(hmd, T_BASE_HMD, DETECTOR, 0, offset, HmdNoiseConfig(calibration_error_m=0.01))
    assert 0.007 < np.linalg.norm(shifted.object_position() - [0.475, 0.1, CUBE / 2]) < 0.013
    shaky = hmd_marker_pose_source(
        hmd, T_BASE_HMD, DETECTOR, 0, offset, HmdNoiseConfig(tracking_noise_m=0.003, tracking_noise_deg=0.3, seed=1)
    )
    errs = [np.linalg.norm(shaky.object_position() - [0.475, 0.1, CUBE / 2]) for _ in range(6)]
    assert 0.002 < np.mean(errs) < 0.015 and np.std(errs) > 0.0005


def test_marker_out_of_view_or_not_seen_is_unavailable(client, cell):
    cube, hmd = cell
    source = hmd_marker_pose_source(hmd, T_BASE_HMD, DETECTOR, 0, np.zeros(3))
    _move(client, cube, (2.0, 2.0))
    with pytest.raises(PoseUnavailable, match="marker 0 not visible"):
        source.object_position()
    wrong_id = hmd_marker_pose_source(hmd, T_BASE_HMD, DETECTOR, 9, np.zeros(3))
    _move(client, cube, (0.5, -0.05))
    with pytest.raises(PoseUnavailable):
        wrong_id.object_position()


def test_from_calibration_checks_dictionary(hl2):
    record = CalibrationRecord(T_BASE_HMD, "DICT_5X5_100", 0.04, "board", 0.0, 0.0, 1, 80)
    with pytest.raises(CalibrationError, match="DICT_5X5_100"):
        MarkerPoseSource.from_calibration(lambda: None, MarkerDetector(DETECTOR), hl2, record, 0)


def test_annotation_pose_source_maps_hmd_points_to_the_base_frame():
    """Against numbers worked out by hand, not against the inverse of the same transform: the HMD world is
    turned 90 deg about z and shifted by (1, 2, 3) m in the base frame, so its x axis is the base's y."""
    T = make_T(rotation_from_rpy_deg(0, 0, 90), [1.0, 2.0, 3.0])
    point = HmdAnnotationPoseSource(lambda: np.array([0.5, 0.0, 0.1]), T)
    assert np.allclose(point.object_position(), [1.0, 2.5, 3.1])
    pose = make_T(rotation_from_rpy_deg(30, 0, 0), [0.0, -0.2, 0.0])  # a pose: its position is used
    assert np.allclose(HmdAnnotationPoseSource(lambda: pose, T).object_position(), [1.2, 2.0, 3.0])


def test_annotation_pose_source_of_a_twin_body(client, cell):
    """The simulated annotator (twin) through the source: exact without noise, the noise passed through."""
    cube, _ = cell
    exact = HmdAnnotationPoseSource(
        annotations_of_body(client, cube, T_BASE_HMD, 0.0, np.random.default_rng(0)), T_BASE_HMD
    )
    assert np.allclose(exact.object_position(), [0.5, -0.05, CUBE / 2], atol=1e-9)
    noisy = HmdAnnotationPoseSource(
        annotations_of_body(client, cube, T_BASE_HMD, 0.004, np.random.default_rng(0)), T_BASE_HMD
    )
    errs = np.array([noisy.object_position() - [0.5, -0.05, CUBE / 2] for _ in range(500)])
    assert np.std(errs, axis=0) == pytest.approx([0.004] * 3, rel=0.15)


@pytest.mark.parametrize(
    "annotation, words",
    [
        (None, "no object annotation"),
        (np.array([0.1, np.nan, 0.0]), "not a finite point"),
        (np.zeros((3, 3)), "shape (3, 3)"),
    ],
)
def test_annotation_pose_source_without_a_usable_annotation_is_unavailable(annotation, words):
    source = HmdAnnotationPoseSource(lambda: annotation, T_BASE_HMD)
    with pytest.raises(PoseUnavailable, match=re.escape(words)):
        source.object_position()


# The check that the calibration package imports neither PyBullet nor torch, also inside functions, is in
# tests/test_robot_pc_imports.py (with the deploy and driver packages).
