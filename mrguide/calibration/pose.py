"""Marker and board pose from detected corners: `SOLVEPNP_IPPE_SQUARE` for one marker, planar PnP for boards."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

from mrguide.calibration.boards import Board, single_marker_corners
from mrguide.calibration.camera_model import CameraModel
from mrguide.calibration.detection import Detections, MarkerDetector, to_gray
from mrguide.calibration.errors import NotEnoughMarkersError
from mrguide.calibration.se3 import from_rvec_tvec, rotation_angle_deg

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PoseEstimate:
    """Pose of a marker or board in the camera frame, with how well it explains the image."""

    T_cam_target: np.ndarray
    reprojection_error_px: float  # RMS over the points used
    n_markers: int
    n_points: int
    ambiguous: bool = False  # two IPPE solutions fit about equally and no prior decided between them


def _rms(obj: np.ndarray, img: np.ndarray, rvec: np.ndarray, tvec: np.ndarray, camera: CameraModel) -> float:
    proj, _ = cv2.projectPoints(obj, rvec, tvec, camera.K, camera.dist_coeffs)
    return float(np.sqrt(np.mean(np.sum((proj.reshape(-1, 2) - img.reshape(-1, 2)) ** 2, axis=1))))


def _candidates(
    obj: np.ndarray, img: np.ndarray, camera: CameraModel, flags: int, z_toward_camera: bool
) -> list[tuple[np.ndarray, np.ndarray, float]]:
    """PnP solutions (rvec, tvec, rms px), best first, that are finite and show the printed side to the camera.

    Besides the IPPE solutions, SQPnP's global solution is a candidate: IPPE returns garbage (tens of px
    error, the plane tilted wildly) for a target seen exactly head-on at the principal point.
    """
    out = []
    for method in (flags, cv2.SOLVEPNP_SQPNP):
        n, rvecs, tvecs, _ = cv2.solvePnPGeneric(obj, img, camera.K, camera.dist_coeffs, flags=method)
        for rvec, tvec in zip(rvecs[:n], tvecs[:n]):
            if not (np.all(np.isfinite(rvec)) and np.all(np.isfinite(tvec))) or tvec[2, 0] <= 0:
                continue
            normal_dot_ray = float(cv2.Rodrigues(rvec)[0][:, 2] @ tvec.reshape(3))
            if (normal_dot_ray < 0) == z_toward_camera:
                out.append((rvec, tvec, _rms(obj, img, rvec, tvec, camera)))
    return sorted(out, key=lambda s: s[2])


def estimate_marker_pose(
    corners: np.ndarray,
    size_m: float,
    camera: CameraModel,
    ambiguity_ratio: float = 0.6,
    normal_hint_cam: np.ndarray | None = None,
) -> PoseEstimate:
    """T_cam_marker of one square marker from its 4 corners (px), marker frame as in `single_marker_corners`.

    IPPE gives two poses for a square; they differ by a flip of the marker plane and fit almost equally
    when the marker is small or seen head-on. The better-fitting one wins unless their error ratio exceeds
    `ambiguity_ratio` and `normal_hint_cam` (the expected marker z axis in the camera frame, e.g. the table
    normal) is given; then the one whose normal agrees best with the hint wins.
    """
    obj = single_marker_corners(size_m)
    img = np.ascontiguousarray(np.asarray(corners, dtype=float).reshape(4, 1, 2))
    sols = _candidates(obj, img, camera, cv2.SOLVEPNP_IPPE_SQUARE, z_toward_camera=True)
    if not sols:
        raise NotEnoughMarkersError("marker pose: no PnP solution shows the marker's front to the camera")
    best, ambiguous = sols[0], False
    R_best = cv2.Rodrigues(best[0])[0]
    flipped = [s for s in sols[1:] if rotation_angle_deg(R_best, cv2.Rodrigues(s[0])[0]) > 1.0]
    if flipped and flipped[0][2] > 0 and best[2] / flipped[0][2] > ambiguity_ratio:
        if normal_hint_cam is None:
            ambiguous = True
        else:
            hint = np.asarray(normal_hint_cam, dtype=float)
            best = max((best, flipped[0]), key=lambda s: float(cv2.Rodrigues(s[0])[0][:, 2] @ hint))
    return PoseEstimate(from_rvec_tvec(best[0], best[1]), best[2], 1, 4, ambiguous)


class BoardPoseEstimator:
    """Pose of a grid or ChArUco board; refuses with NotEnoughMarkersError below `min_markers` board markers."""

    def __init__(self, board: Board, detector: MarkerDetector, min_markers: int = 4):
        self.board = board
        self.detector = detector
        self.min_markers = min_markers
        self._board_ids = set(board.ids.tolist())
        if board.cfg.kind == "charuco":
            self._charuco_params = cv2.aruco.CharucoParameters()
            self._charuco = cv2.aruco.CharucoDetector(board.charuco, self._charuco_params, detector.params)

    def estimate(
        self, image: np.ndarray, camera: CameraModel, detections: Detections | None = None, where: str = "image"
    ) -> tuple[PoseEstimate, Detections]:
        """Board pose in the camera frame and the board markers used (detected, or recovered by refinement)."""
        gray = to_gray(image, where)
        det = detections if detections is not None else self.detector.detect(gray, where, camera)
        mine = det.only(self._board_ids)
        if self.board.cfg.kind == "grid":
            mine = self._refine(gray, mine, camera)
        if len(mine) < self.min_markers:
            raise NotEnoughMarkersError(
                f"{where}: {len(mine)} of the board's {len(self._board_ids)} markers visible "
                f"({sorted(mine.ids.tolist())}); at least {self.min_markers} are required"
            )
        if self.board.cfg.kind == "grid":
            corners, ids = mine.as_opencv()
            obj, img = self.board.board.matchImagePoints(corners, ids)
        else:
            obj, img = self._charuco_points(gray, mine, camera, where)
        return self._solve(obj, img, camera, len(mine)), mine

    def _refine(self, gray: np.ndarray, det: Detections, camera: CameraModel) -> Detections:
        if len(det) == 0:
            return det
        corners, ids = det.as_opencv()
        refined, refined_ids, _, recovered = self.detector.detector.refineDetectedMarkers(
            gray, self.board.board, corners, ids, det.rejected, camera.K, camera.dist_coeffs
        )
        if recovered is not None and len(recovered):
            log.debug("board refinement recovered %d markers", len(recovered))
        return Detections.from_opencv(refined, refined_ids)

    def _charuco_points(self, gray: np.ndarray, det: Detections, camera: CameraModel, where: str):
        self._charuco_params.cameraMatrix = camera.K
        self._charuco_params.distCoeffs = camera.dist_coeffs
        self._charuco.setCharucoParameters(self._charuco_params)
        corners, ids = det.as_opencv()
        ch_corners, ch_ids, _, _ = self._charuco.detectBoard(gray, markerCorners=corners, markerIds=ids)
        n = 0 if ch_ids is None else len(ch_ids)
        if n < 4 or self.board.charuco.checkCharucoCornersCollinear(ch_ids):
            raise NotEnoughMarkersError(
                f"{where}: only {n} ChArUco corners found (or all on one line); need 4 spread ones"
            )
        # the stub wants a sequence of arrays (InputArrayOfArrays); the ChArUco corners are one (n, 1, 2) array
        return self.board.board.matchImagePoints(ch_corners, ch_ids)  # type: ignore[call-overload]

    @staticmethod
    def _solve(obj: np.ndarray, img: np.ndarray, camera: CameraModel, n_markers: int) -> PoseEstimate:
        obj = np.ascontiguousarray(obj, dtype=float).reshape(-1, 3)
        img = np.ascontiguousarray(img, dtype=float).reshape(-1, 1, 2)
        sols = _candidates(obj, img, camera, cv2.SOLVEPNP_IPPE, z_toward_camera=False)
        if not sols:
            raise NotEnoughMarkersError("board pose: no PnP solution shows the board's front to the camera")
        rvec, tvec, _ = sols[0]
        rvec, tvec = cv2.solvePnPRefineLM(obj, img, camera.K, camera.dist_coeffs, rvec.copy(), tvec.copy())
        return PoseEstimate(from_rvec_tvec(rvec, tvec), _rms(obj, img, rvec, tvec, camera), n_markers, len(obj))
