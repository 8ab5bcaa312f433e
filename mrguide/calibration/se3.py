"""Rigid transforms as 4x4 matrices (`T_a_b` maps frame-b coordinates to frame a) and rotation helpers."""

from __future__ import annotations

import cv2
import numpy as np
from numpy.typing import ArrayLike


def make_T(R: ArrayLike, t: ArrayLike) -> np.ndarray:
    """4x4 transform from a 3x3 rotation and a translation (3,)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(t, dtype=float).reshape(3)
    return T


def invert(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform."""
    R, t = T[:3, :3], T[:3, 3]
    return make_T(R.T, -R.T @ t)


def apply(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Transform points (N, 3) or (3,) by T."""
    p = np.asarray(points, dtype=float)
    return p @ T[:3, :3].T + T[:3, 3]


def from_rvec_tvec(rvec: np.ndarray, tvec: np.ndarray) -> np.ndarray:
    """4x4 transform from an OpenCV rotation vector and translation."""
    R, _ = cv2.Rodrigues(np.asarray(rvec, dtype=float).reshape(3, 1))
    return make_T(R, tvec)


def to_rvec_tvec(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV rotation vector (3, 1) and translation (3, 1) of a transform."""
    rvec, _ = cv2.Rodrigues(np.ascontiguousarray(T[:3, :3]))
    return rvec, T[:3, 3].reshape(3, 1).copy()


def rotation_about(axis: np.ndarray, angle_rad: float) -> np.ndarray:
    """3x3 rotation by `angle_rad` about `axis` (any non-zero length)."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    R, _ = cv2.Rodrigues((a * angle_rad).reshape(3, 1))
    return R


def rotation_angle_deg(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle (deg) of the rotation taking R_a to R_b."""
    c = (np.trace(R_a.T @ R_b) - 1.0) / 2.0
    return float(np.degrees(np.arccos(np.clip(c, -1.0, 1.0))))


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation matrix closest to M in the Frobenius norm."""
    U, _, Vt = np.linalg.svd(M)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def mean_rotation(Rs: np.ndarray) -> np.ndarray:
    """Chordal L2 mean of rotations (K, 3, 3)."""
    return nearest_rotation(np.sum(np.asarray(Rs, dtype=float), axis=0))


def is_rigid(T: np.ndarray, tol: float = 1e-6) -> bool:
    """True if T is a finite 4x4 rigid transform (orthonormal rotation, det +1, last row 0 0 0 1)."""
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        return False
    R = T[:3, :3]
    return (
        np.allclose(R.T @ R, np.eye(3), atol=tol)
        and abs(np.linalg.det(R) - 1.0) < tol
        and np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=tol)
    )


def random_unit_vector(rng: np.random.Generator) -> np.ndarray:
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def perturbation(rng: np.random.Generator, translation_m: float, rotation_deg: float) -> np.ndarray:
    """A transform with exactly this translation norm and rotation angle, in random directions."""
    R = rotation_about(random_unit_vector(rng), np.radians(rotation_deg)) if rotation_deg else np.eye(3)
    return make_T(R, random_unit_vector(rng) * translation_m)


def gaussian_noise(rng: np.random.Generator, sigma_m: float, sigma_deg: float) -> np.ndarray:
    """A transform whose translation and rotation vector have i.i.d. N(0, sigma^2) components."""
    rvec = rng.normal(0.0, np.radians(sigma_deg), 3) if sigma_deg > 0 else np.zeros(3)
    t = rng.normal(0.0, sigma_m, 3) if sigma_m > 0 else np.zeros(3)
    return from_rvec_tvec(rvec, t)


def rotation_from_rpy_deg(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """Rz(yaw) @ Ry(pitch) @ Rx(roll), angles in degrees (fixed-axis roll, pitch, yaw as in URDF)."""
    r, p, y = np.radians([roll, pitch, yaw])
    Rx = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    Ry = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    Rz = np.array([[np.cos(y), -np.sin(y), 0], [np.sin(y), np.cos(y), 0], [0, 0, 1]])
    return Rz @ Ry @ Rx
