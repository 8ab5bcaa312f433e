"""Object pose sources for deployment that go through the HMD calibration (implement `ObjectPoseSource`)."""

from __future__ import annotations

import logging
from typing import Callable

import numpy as np

from mrguide.calibration.calibration_file import CalibrationRecord
from mrguide.calibration.camera_model import CameraModel
from mrguide.calibration.detection import MarkerDetector, canonical_dictionary_name
from mrguide.calibration.errors import CalibrationError
from mrguide.calibration.hmd import FrameProvider
from mrguide.calibration.pose import PoseEstimate, estimate_marker_pose
from mrguide.calibration.se3 import apply, invert
from mrguide.pose_source import PoseUnavailable

log = logging.getLogger(__name__)


class MarkerPoseSource:
    """The object position from a marker on the object, seen by the HMD camera.

    position = T_base_hmd @ T_hmd_cam @ T_cam_marker @ offset_marker_to_object, with T_hmd_cam from the
    frame's head tracking and T_base_hmd from the calibration. The marker's expected normal in the base
    frame (`normal_hint_base`, up for a marker on top of the object) settles IPPE's two-fold ambiguity.
    """

    def __init__(self, frames: FrameProvider, detector: MarkerDetector, camera: CameraModel, T_base_hmd: np.ndarray,
                 marker_id: int, offset_marker_to_object: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0),
                 normal_hint_base: np.ndarray | tuple[float, float, float] | None = (0.0, 0.0, 1.0)):
        self.frames, self.detector, self.camera = frames, detector, camera
        self.T_base_hmd = np.asarray(T_base_hmd, dtype=float)
        self.marker_id = marker_id
        self.offset = np.asarray(offset_marker_to_object, dtype=float).reshape(3)
        self.normal_hint_base = None if normal_hint_base is None else np.asarray(normal_hint_base, dtype=float)
        self.last_pose: PoseEstimate | None = None

    @classmethod
    def from_calibration(cls, frames: FrameProvider, detector: MarkerDetector, camera: CameraModel,
                         calibration: CalibrationRecord, marker_id: int,
                         offset_marker_to_object: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0),
                         ) -> "MarkerPoseSource":
        """As the constructor, after checking that the calibration used the detector's dictionary."""
        if canonical_dictionary_name(calibration.dictionary) != canonical_dictionary_name(detector.cfg.dictionary):
            raise CalibrationError(
                f"calibration used dictionary {calibration.dictionary} but the detector uses {detector.cfg.dictionary}"
            )
        return cls(frames, detector, camera, calibration.T_base_hmd, marker_id, offset_marker_to_object)

    def object_position(self) -> np.ndarray:
        frame = self.frames()
        self.camera.check_image(frame.image, "HMD frame")
        corners = self.detector.detect(frame.image, "HMD frame", self.camera).corners_of(self.marker_id)
        if corners is None:
            raise PoseUnavailable(f"marker {self.marker_id} not visible")
        T_base_cam = self.T_base_hmd @ frame.T_hmd_cam
        hint = None if self.normal_hint_base is None else invert(T_base_cam)[:3, :3] @ self.normal_hint_base
        pose = estimate_marker_pose(corners, self.detector.marker_size_m, self.camera,
                                    self.detector.cfg.ambiguity_ratio, hint)
        if pose.ambiguous:
            raise PoseUnavailable(f"marker {self.marker_id}: pose ambiguous (two IPPE solutions fit equally)")
        self.last_pose = pose
        return apply(T_base_cam @ pose.T_cam_target, self.offset)


class HmdAnnotationPoseSource:
    """The object position from an MR annotation made in the HMD world frame (a point (3,) or a pose (4, 4)),
    mapped to the robot base frame by the calibration. The provider returns None when there is none."""

    def __init__(self, annotations: Callable[[], np.ndarray | None], T_base_hmd: np.ndarray):
        self.annotations = annotations
        self.T_base_hmd = np.asarray(T_base_hmd, dtype=float)

    def object_position(self) -> np.ndarray:
        a = self.annotations()
        if a is None:
            raise PoseUnavailable("no object annotation from the HMD")
        a = np.asarray(a, dtype=float)
        if a.shape == (4, 4):
            a = a[:3, 3]
        if a.shape != (3,) or not np.all(np.isfinite(a)):
            raise PoseUnavailable(f"HMD annotation is not a finite point or pose: shape {a.shape}")
        return apply(self.T_base_hmd, a)
