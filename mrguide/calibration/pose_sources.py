"""Object pose sources for deployment that go through the HMD calibration (implement `ObjectPoseSource`)."""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mrguide.calibration.calibration_file import CalibrationRecord
from mrguide.calibration.camera_model import CameraModel
from mrguide.calibration.detection import Detections, MarkerDetector, canonical_dictionary_name
from mrguide.calibration.errors import CalibrationError, NotEnoughMarkersError
from mrguide.calibration.hmd import FrameProvider, HmdFrame
from mrguide.calibration.pose import PoseEstimate, estimate_marker_pose
from mrguide.calibration.se3 import apply, invert
from mrguide.pose_source import PoseUnavailable

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class MarkerObservation:
    """What one frame showed: the detections, the object marker's pose (camera frame) and the object position
    (base frame), or why there is none."""

    detections: Detections
    pose: PoseEstimate | None
    position: np.ndarray | None
    problem: str = ""


class MarkerPoseSource:
    """The object position from a marker on the object, seen by the HMD camera.

    position = T_base_hmd @ T_hmd_cam @ T_cam_marker @ offset_marker_to_object, with T_hmd_cam from the
    frame's head tracking and T_base_hmd from the calibration (for a fixed camera T_hmd_cam = I). `frames` may be
    None when the caller hands frames to `observe` itself. The marker's expected normal in the base
    frame (`normal_hint_base`, up for a marker on top of the object) settles IPPE's two-fold ambiguity.
    """

    def __init__(
        self,
        frames: FrameProvider | None,
        detector: MarkerDetector,
        camera: CameraModel,
        T_base_hmd: np.ndarray,
        marker_id: int,
        offset_marker_to_object: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0),
        normal_hint_base: np.ndarray | tuple[float, float, float] | None = (0.0, 0.0, 1.0),
    ):
        self.frames, self.detector, self.camera = frames, detector, camera
        self.T_base_hmd = np.asarray(T_base_hmd, dtype=float)
        self.marker_id = marker_id
        self.offset = np.asarray(offset_marker_to_object, dtype=float).reshape(3)
        self.normal_hint_base = None if normal_hint_base is None else np.asarray(normal_hint_base, dtype=float)
        self.last_pose: PoseEstimate | None = None

    @classmethod
    def from_calibration(
        cls,
        frames: FrameProvider,
        detector: MarkerDetector,
        camera: CameraModel,
        calibration: CalibrationRecord,
        marker_id: int,
        offset_marker_to_object: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0),
    ) -> MarkerPoseSource:
        """As the constructor, after checking that the calibration used the detector's dictionary."""
        if canonical_dictionary_name(calibration.dictionary) != canonical_dictionary_name(detector.cfg.dictionary):
            raise CalibrationError(
                f"calibration used dictionary {calibration.dictionary} but the detector uses {detector.cfg.dictionary}"
            )
        return cls(frames, detector, camera, calibration.T_base_hmd, marker_id, offset_marker_to_object)

    def observe(self, frame: HmdFrame) -> MarkerObservation:
        """Detect the marker in one frame and map its pose to the object position in the base frame."""
        self.camera.check_image(frame.image, "camera frame")
        detections = self.detector.detect(frame.image, "camera frame", self.camera)
        corners = detections.corners_of(self.marker_id)
        if corners is None:
            return MarkerObservation(detections, None, None, f"marker {self.marker_id} not visible")
        T_base_cam = self.T_base_hmd @ frame.T_hmd_cam
        hint = None if self.normal_hint_base is None else invert(T_base_cam)[:3, :3] @ self.normal_hint_base
        try:
            pose = estimate_marker_pose(
                corners, self.detector.marker_size_m, self.camera, self.detector.cfg.ambiguity_ratio, hint
            )
        except NotEnoughMarkersError as exc:  # no PnP solution shows the marker's front
            return MarkerObservation(detections, None, None, f"marker {self.marker_id}: {exc}")
        if pose.ambiguous:
            return MarkerObservation(
                detections, pose, None, f"marker {self.marker_id}: pose ambiguous (two IPPE solutions fit equally)"
            )
        self.last_pose = pose
        return MarkerObservation(detections, pose, apply(T_base_cam @ pose.T_cam_target, self.offset))

    def object_position(self) -> np.ndarray:
        if self.frames is None:
            raise TypeError("MarkerPoseSource without a frame provider: call observe(frame)")
        seen = self.observe(self.frames())
        if seen.position is None:
            raise PoseUnavailable(seen.problem)
        return seen.position


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
