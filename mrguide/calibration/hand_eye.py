"""Robot-world / hand-eye calibration for a marker carried by the robot: solve A_i X = Z B_i.

A_i = T_base_tcp (robot forward kinematics), B_i = T_hmd_marker (marker pose through the HMD camera and
head tracking), X = T_tcp_marker (where the marker sits on the tool), Z = T_base_hmd (the calibration).
With a fixed camera and no head tracking, pass T_hmd_marker = T_cam_marker: Z is then T_base_cam.

OpenCV's `calibrateRobotWorldHandEye` is used where the installed cv2 has it; the opencv-python 5.0.0.93
wheels lack the binding (opencv/opencv#29565, fixed by #29584), and then the same closed-form method
(Shah 2013: Kronecker-product rotation, linear least-squares translation) runs in numpy.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from mrguide.calibration.calibration_file import CalibrationRecord
from mrguide.calibration.detection import canonical_dictionary_name
from mrguide.calibration.errors import CalibrationError, NotEnoughMarkersError
from mrguide.calibration.se3 import invert, make_T, nearest_rotation, rotation_angle_deg

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class HandEyeResult:
    T_base_hmd: np.ndarray
    T_tcp_marker: np.ndarray
    translation_residuals_m: np.ndarray  # per pose: |A X - Z B| translation
    rotation_residuals_deg: np.ndarray  # per pose: angle between A X and Z B
    solver: str  # "opencv" or "numpy"

    @property
    def rms_m(self) -> float:
        return float(np.sqrt(np.mean(self.translation_residuals_m**2)))

    @property
    def max_m(self) -> float:
        return float(np.max(self.translation_residuals_m))

    def record(self, dictionary: str, marker_size_m: float, camera: dict | None = None) -> CalibrationRecord:
        """The calibration file record of this result (T_tcp_marker and rotation residuals go in `extra`)."""
        return CalibrationRecord(
            T_base_hmd=self.T_base_hmd,
            dictionary=canonical_dictionary_name(dictionary),
            marker_size_m=marker_size_m,
            method="hand-eye",
            rms_residual_m=self.rms_m,
            max_residual_m=self.max_m,
            n_frames=len(self.translation_residuals_m),
            n_points=len(self.translation_residuals_m),
            camera=camera,
            extra={
                "T_tcp_marker": self.T_tcp_marker.tolist(),
                "solver": self.solver,
                "rotation_residuals_deg": self.rotation_residuals_deg.tolist(),
            },
        )


def _shah(A: list[np.ndarray], B: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """X, Z of A_i X = Z B_i by Shah's closed form."""
    I3 = np.eye(3)
    K = np.vstack([np.hstack([np.kron(I3, a[:3, :3]), -np.kron(b[:3, :3].T, I3)]) for a, b in zip(A, B)])
    _, s, Vt = np.linalg.svd(K)
    if s[-2] < 1e-6 * s[0]:
        raise CalibrationError(
            "hand-eye: the robot poses do not determine the rotation; rotate the tool about at least two different axes"
        )
    v = Vt[-1]
    Rx, Rz = v[:9].reshape(3, 3, order="F"), v[9:].reshape(3, 3, order="F")
    scale = np.sign(np.linalg.det(Rx)) / abs(np.linalg.det(Rx)) ** (1.0 / 3.0)
    Rx, Rz = nearest_rotation(scale * Rx), nearest_rotation(scale * Rz)
    M = np.vstack([np.hstack([a[:3, :3], -I3]) for a in A])
    rhs = np.concatenate([Rz @ b[:3, 3] - a[:3, 3] for a, b in zip(A, B)])
    t = np.linalg.lstsq(M, rhs, rcond=None)[0]
    return make_T(Rx, t[:3]), make_T(Rz, t[3:])


def _opencv(A: list[np.ndarray], B: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """X, Z through cv2.calibrateRobotWorldHandEye (its 'camera' is our marker, its 'world' our HMD frame)."""
    world2cam = [invert(b) for b in B]  # T_marker_hmd
    base2gripper = [invert(a) for a in A]  # T_tcp_base
    # not in the 5.0.0 bindings nor their stubs (opencv#29565): called only where the installed cv2 has it. The
    # translations go as 3 x 1 columns: 5.1 refuses flat vectors (an assertion in gemm), 4.x took either.
    R_b2w, t_b2w, R_g2c, t_g2c = cv2.calibrateRobotWorldHandEye(  # type: ignore[attr-defined,unused-ignore]
        [m[:3, :3] for m in world2cam],
        [m[:3, 3:4] for m in world2cam],
        [m[:3, :3] for m in base2gripper],
        [m[:3, 3:4] for m in base2gripper],
        method=cv2.CALIB_ROBOT_WORLD_HAND_EYE_SHAH,
    )
    return invert(make_T(R_g2c, t_g2c.reshape(3))), invert(make_T(R_b2w, t_b2w.reshape(3)))


def solve_robot_world_hand_eye(T_base_tcp: Sequence[np.ndarray], T_hmd_marker: Sequence[np.ndarray]) -> HandEyeResult:
    """T_base_hmd and T_tcp_marker from >= 3 robot poses with the marker seen at each."""
    A = [np.asarray(a, dtype=float) for a in T_base_tcp]
    B = [np.asarray(b, dtype=float) for b in T_hmd_marker]
    if len(A) != len(B):
        raise CalibrationError(f"hand-eye: {len(A)} robot poses but {len(B)} marker poses")
    if len(A) < 3:
        raise NotEnoughMarkersError(f"hand-eye: {len(A)} poses with the marker seen; at least 3 are required")
    if hasattr(cv2, "calibrateRobotWorldHandEye"):
        X, Z = _opencv(A, B)
        solver = "opencv"
    else:
        X, Z = _shah(A, B)
        solver = "numpy"
    lhs = [a @ X for a in A]
    rhs = [Z @ b for b in B]
    res = HandEyeResult(
        T_base_hmd=Z,
        T_tcp_marker=X,
        translation_residuals_m=np.array([np.linalg.norm(a[:3, 3] - b[:3, 3]) for a, b in zip(lhs, rhs)]),
        rotation_residuals_deg=np.array([rotation_angle_deg(a[:3, :3], b[:3, :3]) for a, b in zip(lhs, rhs)]),
        solver=solver,
    )
    log.info(
        "hand-eye (%s): %d poses, rms %.2f mm, max rotation residual %.2f deg",
        solver,
        len(A),
        res.rms_m * 1e3,
        float(res.rotation_residuals_deg.max()),
    )
    return res
