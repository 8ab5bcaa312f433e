"""The calibration procedure: frames (image + head-tracked camera pose) in, registration and file record out."""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from mrguide.calibration.calibration_file import CalibrationRecord
from mrguide.calibration.camera_model import CameraModel
from mrguide.calibration.config import CalibrationConfig
from mrguide.calibration.detection import MarkerDetector, canonical_dictionary_name
from mrguide.calibration.overlay import draw_overlay
from mrguide.calibration.registration import Correspondences, Registration, register
from mrguide.calibration.targets import TargetObserver, layout_from_config

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class CalibrationRun:
    """Everything a calibration produced: the record to save, the registration, per-frame data, overlays."""

    record: CalibrationRecord
    registration: Registration
    frames: tuple[Correspondences, ...]
    overlays: tuple[np.ndarray, ...]  # BGR, one per frame


def calibrate_frames(
    frames: Iterable[tuple[str, np.ndarray, np.ndarray]], cfg: CalibrationConfig, camera: CameraModel
) -> CalibrationRun:
    """Register the HMD frame to the robot base from (label, image, T_hmd_cam) frames of the configured targets."""
    detector = MarkerDetector(cfg.detector)
    layout = layout_from_config(cfg, detector)
    observer = TargetObserver(layout, detector, camera, cfg.registration.min_markers)
    observed, overlays = [], []
    for label, image, T_hmd_cam in frames:
        corr, det, poses = observer.observe(image, T_hmd_cam, label)
        observed.append(corr)
        overlays.append(draw_overlay(image, det, poses, camera, f"{label}: {corr.n_markers} target markers"))
        log.info("%s: %d markers detected, %d target markers used", label, len(det), corr.n_markers)
    reg = register(observed, cfg.registration)
    method = "+".join(
        name for name, used in (("board", layout.board is not None), ("markers", bool(layout.markers))) if used
    )
    record = CalibrationRecord(
        T_base_hmd=reg.T_base_hmd,
        dictionary=canonical_dictionary_name(cfg.detector.dictionary),
        marker_size_m=cfg.detector.marker_size_m,
        method=method,
        rms_residual_m=reg.rms_m,
        max_residual_m=reg.max_m,
        n_frames=len(reg.frames_used),
        n_points=len(reg.residuals_m),
        camera=camera.to_dict(),
        board=dataclasses.asdict(cfg.board) if layout.board is not None else None,
        extra={
            "frames_used": list(reg.frames_used),
            "frames_rejected": reg.frames_rejected,
            "targets": dataclasses.asdict(cfg.targets),
        },
    )
    return CalibrationRun(record, reg, tuple(observed), tuple(overlays))
