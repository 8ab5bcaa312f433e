"""Rigid registration of the HMD (or camera) frame to the robot base frame from corresponding 3D points.

Each frame contributes target points measured in the HMD frame (through the marker/board pose and head
tracking) and the same points known in the base frame. Every frame gets its own Kabsch fit; frames whose
fit is far from the robust centre of all fits are rejected; one fit over the remaining frames' points gives
T_base_hmd and the per-point residuals.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from mrguide.calibration.config import RegistrationConfig
from mrguide.calibration.errors import CalibrationError, NotEnoughMarkersError
from mrguide.calibration.se3 import apply, make_T, rotation_angle_deg

log = logging.getLogger(__name__)


class _Residuals:
    """RMS and maximum of a `residuals_m` array (m)."""

    residuals_m: np.ndarray

    @property
    def rms_m(self) -> float:
        return float(np.sqrt(np.mean(self.residuals_m**2)))

    @property
    def max_m(self) -> float:
        return float(np.max(self.residuals_m))


@dataclass(frozen=True)
class RigidFit(_Residuals):
    """T_dst_src with the distance of every transformed source point from its destination point (m)."""

    T_dst_src: np.ndarray
    residuals_m: np.ndarray


def fit_rigid(src: np.ndarray, dst: np.ndarray, where: str = "rigid fit") -> RigidFit:
    """Least-squares rotation and translation taking points `src` (N, 3) onto `dst` (Kabsch / Umeyama, no scale)."""
    src, dst = np.asarray(src, dtype=float), np.asarray(dst, dtype=float)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3:
        raise CalibrationError(f"{where}: need two (N, 3) point sets of equal size, got {src.shape} and {dst.shape}")
    if len(src) < 3:
        raise NotEnoughMarkersError(f"{where}: {len(src)} point pairs; a rigid transform needs at least 3")
    cs, cd = src.mean(axis=0), dst.mean(axis=0)
    spread = np.linalg.svd(src - cs, compute_uv=False)
    if spread[1] <= 1e-3 * spread[0]:
        raise CalibrationError(f"{where}: the points lie on one line; the rotation about it is undetermined")
    U, _, Vt = np.linalg.svd((src - cs).T @ (dst - cd))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    T = make_T(R, cd - R @ cs)
    return RigidFit(T, np.linalg.norm(apply(T, src) - dst, axis=1))


@dataclass(frozen=True)
class Correspondences:
    """One frame's target points: measured in the HMD frame, known in the base frame, and how many markers."""

    label: str
    points_hmd: np.ndarray
    points_base: np.ndarray
    n_markers: int


@dataclass(frozen=True)
class Registration(_Residuals):
    """T_base_hmd from the frames that agreed, with residuals and what was left out and why."""

    T_base_hmd: np.ndarray
    residuals_m: np.ndarray  # per point, over all frames used
    frames_used: tuple[str, ...]
    frames_rejected: dict[str, str] = field(default_factory=dict)  # label -> reason


def register(frames: Sequence[Correspondences], cfg: RegistrationConfig = RegistrationConfig()) -> Registration:
    """T_base_hmd from frames of correspondences, rejecting frames with too few markers and outlier frames."""
    rejected: dict[str, str] = {}
    usable = []
    for f in frames:
        if f.n_markers < cfg.min_markers:
            rejected[f.label] = f"{f.n_markers} target markers usable, {cfg.min_markers} required"
        else:
            usable.append(f)
    if len(usable) < cfg.min_frames:
        detail = "; ".join(f"{k}: {v}" for k, v in rejected.items()) or "no frames given"
        raise NotEnoughMarkersError(f"registration: {len(usable)} usable frames, {cfg.min_frames} required ({detail})")
    fits = [fit_rigid(f.points_hmd, f.points_base, f"frame {f.label}") for f in usable]
    inliers = _consistent(usable, fits, cfg, rejected)
    if len(inliers) < cfg.min_frames:
        raise CalibrationError(
            f"registration: only {len(inliers)} of {len(usable)} frames agree with each other "
            f"({cfg.min_frames} required): " + "; ".join(f"{k}: {v}" for k, v in rejected.items())
        )
    fit = fit_rigid(
        np.vstack([f.points_hmd for f in inliers]), np.vstack([f.points_base for f in inliers]), "registration"
    )
    reg = Registration(fit.T_dst_src, fit.residuals_m, tuple(f.label for f in inliers), rejected)
    log.info(
        "registration: %d frames, %d points, rms %.2f mm, max %.2f mm, %d frames rejected",
        len(inliers),
        len(fit.residuals_m),
        reg.rms_m * 1e3,
        reg.max_m * 1e3,
        len(rejected),
    )
    if reg.rms_m > cfg.max_rms_residual_m:
        log.warning(
            "registration rms residual %.1f mm exceeds %.1f mm: check the target placement and the images",
            reg.rms_m * 1e3,
            cfg.max_rms_residual_m * 1e3,
        )
    return reg


def _consistent(
    frames: list[Correspondences], fits: list[RigidFit], cfg: RegistrationConfig, rejected: dict[str, str]
) -> list[Correspondences]:
    """The frames whose own fit lies near the robust centre of all fits (median translation, medoid rotation)."""
    if len(fits) < 3:  # with one or two frames there is no majority to judge by
        return frames
    t = np.array([f.T_dst_src[:3, 3] for f in fits])
    Rs = [f.T_dst_src[:3, :3] for f in fits]
    t_med = np.median(t, axis=0)
    angles = np.array([[rotation_angle_deg(a, b) for b in Rs] for a in Rs])
    R_ref = Rs[int(np.argmin(np.median(angles, axis=1)))]
    keep = []
    for f, _fit, ti, Ri in zip(frames, fits, t, Rs):
        dt, dr = float(np.linalg.norm(ti - t_med)), rotation_angle_deg(Ri, R_ref)
        if dt > cfg.outlier_translation_m or dr > cfg.outlier_rotation_deg:
            rejected[f.label] = f"outlier: {dt * 1e3:.1f} mm / {dr:.2f} deg from the other frames"
            log.warning("registration: frame %s rejected (%s)", f.label, rejected[f.label])
        else:
            keep.append(f)
    return keep
