"""Detection: dictionaries, image checks, the twin's marker textures, and corner refinement."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.calibration.boards import marker_pose_on_table, single_marker_corners
from mrguide.calibration.camera_model import CameraModel, load_camera_model
from mrguide.calibration.config import DetectorConfig
from mrguide.calibration.detection import MarkerDetector, canonical_dictionary_name, get_dictionary
from mrguide.calibration.errors import CalibrationError
from mrguide.calibration.se3 import apply
from mrguide.twin.camera import Camera
from mrguide.twin.markers import HOLOLENS2_PV, add_marker_plane, render


def test_dictionary_names():
    assert canonical_dictionary_name("4x4_50") == "DICT_4X4_50"
    assert get_dictionary("DICT_APRILTAG_36h11").markerSize == 6
    with pytest.raises(CalibrationError, match=r"unknown ArUco dictionary 'DICT_4X4_51'.*DICT_4X4_50"):
        MarkerDetector(DetectorConfig(dictionary="DICT_4X4_51"))


def test_bad_images_are_refused(hl2):
    det = MarkerDetector()
    with pytest.raises(CalibrationError, match="uint8"):
        det.detect(np.zeros((10, 10), np.float32))
    with pytest.raises(CalibrationError, match="shape"):
        det.detect(np.zeros((10, 10, 4), np.uint8))
    with pytest.raises(CalibrationError, match="640x480 but the intrinsics are for 1280x720"):
        hl2.check_image(np.zeros((480, 640, 3), np.uint8), "frame.png")


def test_intrinsics_files(tmp_path):
    (tmp_path / "k.json").write_text(
        '{"width": 1280, "height": 720, "camera_matrix": [[1000, 0, 640], [0, 1001, 360], [0, 0, 1]], "dist": [0.1, 0, 0, 0, 0]}'
    )
    cam = load_camera_model(tmp_path / "k.json")
    assert (cam.fx, cam.fy, cam.cx, cam.dist[0]) == (1000.0, 1001.0, 640.0, 0.1)
    (tmp_path / "k.toml").write_text("width = 640\nheight = 480\nfx = 600\nfy = 600\ncx = 320\ncy = 240\n")
    assert load_camera_model(tmp_path / "k.toml") == CameraModel(640, 480, 600.0, 600.0, 320.0, 240.0)
    (tmp_path / "bad.json").write_text('{"width": 1280, "height": 720, "fx": 1000}')
    with pytest.raises(CalibrationError, match="missing intrinsics key 'fy'"):
        load_camera_model(tmp_path / "bad.json")
    with pytest.raises(CalibrationError, match="not found"):
        load_camera_model(tmp_path / "none.json")


@pytest.fixture
def marker_scene(client, orbit):
    """A 6 cm marker (id 7) on the table, and three oblique views of it at 0.5-0.9 m."""
    T_base_marker = marker_pose_on_table((0.5, 0.1, 0.0005), 25.0)
    add_marker_plane(client, "DICT_4X4_50", 7, 0.06, T_base_marker)
    cams = [
        Camera(client, orbit([0.5, 0.1, 0.0], d, tilt, az), HOLOLENS2_PV)
        for d, tilt, az in ((0.5, 35, 200), (0.7, 50, 120), (0.9, 20, 300))
    ]
    return T_base_marker, cams


def test_texture_corners_land_on_projected_corners(marker_scene):
    """The marker texture is mapped so that detected image corners match the projected 3D corners."""
    T_base_marker, cams = marker_scene
    det = MarkerDetector(DetectorConfig(marker_size_m=0.06))
    for cam in cams:
        found = det.detect(render(cam)).corners_of(7)
        expected = cam.project(apply(T_base_marker, single_marker_corners(0.06)))
        assert found is not None
        assert np.max(np.linalg.norm(found - expected, axis=1)) < 0.25


def test_edge_refinement_beats_opencv_subpix(marker_scene):
    """cornerSubPix pulls convex marker corners inwards; the edge fits remove that bias."""
    T_base_marker, cams = marker_scene
    errors = {}
    for method in ("subpix", "edges"):
        det = MarkerDetector(DetectorConfig(marker_size_m=0.06, corner_refinement=method))
        errs = []
        for cam in cams:
            found = det.detect(render(cam)).corners_of(7)
            errs.append(np.linalg.norm(found - cam.project(apply(T_base_marker, single_marker_corners(0.06))), axis=1))
        errors[method] = float(np.mean(errs))
    assert errors["edges"] < 0.1 < errors["subpix"]
