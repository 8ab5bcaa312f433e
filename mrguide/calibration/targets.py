"""Calibration targets at known robot-frame poses, and what one HMD frame measures of them.

A target layout holds a board (placed from its pose or from TCP-touched outline corners) and/or single
markers lying on the table. `observe` turns one image plus its head-tracked camera pose into
correspondences for `registration.register`: target points measured in the HMD frame, paired with the
same points known in the base frame.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from mrguide.calibration.boards import (
    Board,
    board_pose_on_table,
    make_board,
    marker_pose_on_table,
    single_marker_corners,
)
from mrguide.calibration.camera_model import CameraModel
from mrguide.calibration.config import CalibrationConfig
from mrguide.calibration.detection import Detections, MarkerDetector
from mrguide.calibration.errors import CalibrationError, NotEnoughMarkersError
from mrguide.calibration.pose import BoardPoseEstimator, PoseEstimate, estimate_marker_pose
from mrguide.calibration.registration import Correspondences, fit_rigid
from mrguide.calibration.se3 import apply, invert

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class TargetLayout:
    """Targets with known poses in the robot base frame."""

    board: Board | None = None
    T_base_board: np.ndarray | None = None  # given with the board
    markers: dict[int, np.ndarray] = field(default_factory=dict)  # id -> T_base_marker
    marker_size_m: float = 0.0

    def __post_init__(self) -> None:
        if self.board is not None and set(self.markers) & set(self.board.ids.tolist()):
            raise CalibrationError(
                f"calibration targets: single marker ids {sorted(self.markers)} overlap the board's ids"
            )
        if self.board is None and not self.markers:
            raise CalibrationError("calibration targets: no board and no markers")


def board_pose_from_touched_corners(board: Board, touched_base: np.ndarray, tolerance_m: float) -> np.ndarray:
    """T_base_board from 3 or 4 outline corners touched with the TCP (order as `Board.outline`)."""
    touched = np.asarray(touched_base, dtype=float)
    fit = fit_rigid(board.outline()[: len(touched)], touched, "touched board corners")
    if fit.max_m > tolerance_m:
        raise CalibrationError(
            f"touched board corners do not match the board outline: worst corner off by {fit.max_m * 1e3:.1f} mm "
            f"(tolerance {tolerance_m * 1e3:.1f} mm); check the corner order (origin, +x, opposite, +y) and the board size"
        )
    log.info("board pose from %d touched corners: rms %.2f mm", len(touched), fit.rms_m * 1e3)
    return fit.T_dst_src


def layout_from_config(cfg: CalibrationConfig, detector: MarkerDetector) -> TargetLayout:
    """The target layout described by `[calibration.targets]` and `[calibration.board]`."""
    t = cfg.targets
    board, T_board = None, None
    if t.use_board:
        board = make_board(cfg.board, detector.dictionary)
        if t.board_touched_corners:
            T_board = board_pose_from_touched_corners(board, np.array(t.board_touched_corners), t.touch_tolerance_m)
        else:
            T_board = board_pose_on_table(t.board_xyz, t.board_yaw_deg)
    markers = {m.id: marker_pose_on_table(m.xyz, m.yaw_deg) for m in t.markers}
    return TargetLayout(board, T_board, markers, cfg.detector.marker_size_m)


class TargetObserver:
    """Measures the layout's targets in images: board by PnP over all its points, single markers by IPPE."""

    def __init__(self, layout: TargetLayout, detector: MarkerDetector, camera: CameraModel, min_markers: int):
        self.layout, self.detector, self.camera = layout, detector, camera
        self.board_estimator = None if layout.board is None else BoardPoseEstimator(layout.board, detector, min_markers)

    def observe(
        self, image: np.ndarray, T_hmd_cam: np.ndarray, label: str
    ) -> tuple[Correspondences, Detections, list[tuple[PoseEstimate, float]]]:
        """Correspondences of one frame (n_markers: the target markers used), plus the detections and the
        poses (with an axis length) for drawing."""
        self.camera.check_image(image, label)
        det = self.detector.detect(image, label, self.camera)
        hmd_pts, base_pts, poses, n_markers = [], [], [], 0
        R_cam_base: np.ndarray | None = None  # base-frame orientation in the camera, seen through the board
        if self.board_estimator is not None:
            try:
                board_pose, used = self.board_estimator.estimate(image, self.camera, det, label)
            except NotEnoughMarkersError as exc:
                log.info("%s", exc)
            else:
                board, T_base_board = self.layout.board, self.layout.T_base_board
                assert board is not None and T_base_board is not None  # there is a board estimator
                pts = np.vstack(list(board.marker_corners().values()))
                hmd_pts.append(apply(T_hmd_cam @ board_pose.T_cam_target, pts))
                base_pts.append(apply(T_base_board, pts))
                poses.append((board_pose, 0.5 * min(board.size_m)))
                n_markers += len(used)
                R_cam_base = (board_pose.T_cam_target @ invert(T_base_board))[:3, :3]
        n_markers += self._single_markers(det, T_hmd_cam, R_cam_base, hmd_pts, base_pts, poses)
        if not hmd_pts:
            return Correspondences(label, np.zeros((0, 3)), np.zeros((0, 3)), n_markers), det, poses
        return Correspondences(label, np.vstack(hmd_pts), np.vstack(base_pts), n_markers), det, poses

    def _single_markers(
        self,
        det: Detections,
        T_hmd_cam: np.ndarray,
        R_cam_base: np.ndarray | None,
        hmd_pts: list,
        base_pts: list,
        poses: list,
    ) -> int:
        """Adds each visible single marker's corners; an IPPE-ambiguous marker is settled by the table normal
        seen through the board or the other markers, or left out."""
        size = self.layout.marker_size_m
        obj = single_marker_corners(size)
        found: dict[int, tuple[np.ndarray, PoseEstimate]] = {}  # id -> (corners, pose)
        for mid in self.layout.markers:
            corners = det.corners_of(mid)
            if corners is not None:
                found[mid] = (
                    corners,
                    estimate_marker_pose(corners, size, self.camera, self.detector.cfg.ambiguity_ratio),
                )
        if R_cam_base is None:
            clear = [(mid, p) for mid, (_, p) in found.items() if not p.ambiguous]
            if clear:
                mid, p = min(clear, key=lambda mp: mp[1].reprojection_error_px)
                R_cam_base = p.T_cam_target[:3, :3] @ self.layout.markers[mid][:3, :3].T
        used = 0
        for mid, (corners, pose) in found.items():
            T_base_marker = self.layout.markers[mid]
            if pose.ambiguous:
                if R_cam_base is None:
                    log.info("marker %d: pose ambiguous and no reference to settle it; left out", mid)
                    continue
                pose = estimate_marker_pose(
                    corners,
                    size,
                    self.camera,
                    self.detector.cfg.ambiguity_ratio,
                    R_cam_base @ T_base_marker[:3, 2],
                )
            hmd_pts.append(apply(T_hmd_cam @ pose.T_cam_target, obj))
            base_pts.append(apply(T_base_marker, obj))
            poses.append((pose, 0.75 * size))
            used += 1
        return used
