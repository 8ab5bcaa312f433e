"""Fixtures for the calibration tests: a PyBullet client, the HoloLens 2 camera model, camera placement."""

from __future__ import annotations

import numpy as np
import pybullet as pb
import pytest

from mrguide.calibration.camera_model import CameraModel
from mrguide.twin.camera import look_at
from mrguide.twin.markers import HOLOLENS2_PV


@pytest.fixture
def client():
    c = pb.connect(pb.DIRECT)
    yield c
    pb.disconnect(c)


@pytest.fixture
def hl2() -> CameraModel:
    return CameraModel.from_pinhole(HOLOLENS2_PV)


@pytest.fixture
def orbit():
    """T_base_cam(target, distance, tilt_deg, azimuth_deg): a camera `distance` from `target`, its line of
    sight `tilt_deg` from the table normal, coming from `azimuth_deg` about z."""

    def make(target, distance: float, tilt_deg: float, azimuth_deg: float = 180.0) -> np.ndarray:
        t, az = np.radians(tilt_deg), np.radians(azimuth_deg)
        target = np.asarray(target, dtype=float)
        eye = target + distance * np.array([np.sin(t) * np.cos(az), np.sin(t) * np.sin(az), np.cos(t)])
        up = np.array([np.cos(az + 0.3), np.sin(az + 0.3), 0.0]) if tilt_deg < 1 else np.array([0.0, 0.0, 1.0])
        return look_at(eye, target, up)

    return make
