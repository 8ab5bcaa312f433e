"""The HMD as the calibration sees it: camera frames with head-tracked poses, and the errors added to them.

The HMD keeps its own world frame ("hmd") from head tracking; every camera frame comes with the camera's
pose in it, `T_hmd_cam`. The marker calibration gives `T_base_hmd`, so a camera-frame point p maps to the
robot base frame as `T_base_hmd @ T_hmd_cam @ p`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from mrguide.calibration.config import HmdNoiseConfig
from mrguide.calibration.se3 import gaussian_noise, make_T, perturbation


@dataclass(frozen=True)
class HmdFrame:
    """One camera image and the head-tracked camera pose at the time it was taken."""

    image: np.ndarray
    T_hmd_cam: np.ndarray


FrameProvider = Callable[[], HmdFrame]


class TrackingNoise:
    """Wraps a frame provider and adds Gaussian head-tracking error (in the camera frame) to every pose."""

    def __init__(self, frames: FrameProvider, sigma_m: float, sigma_deg: float, rng: np.random.Generator):
        self.frames = frames
        self.sigma_m, self.sigma_deg = sigma_m, sigma_deg
        self.rng = rng

    def __call__(self) -> HmdFrame:
        f = self.frames()
        return HmdFrame(f.image, f.T_hmd_cam @ gaussian_noise(self.rng, self.sigma_m, self.sigma_deg))


def with_tracking_noise(frames: FrameProvider, cfg: HmdNoiseConfig) -> FrameProvider:
    """`frames` with the configured tracking noise (unchanged when the noise is zero)."""
    if cfg.tracking_noise_m == 0 and cfg.tracking_noise_deg == 0:
        return frames
    return TrackingNoise(frames, cfg.tracking_noise_m, cfg.tracking_noise_deg, np.random.default_rng(cfg.seed))


def with_calibration_error(T_base_hmd: np.ndarray, cfg: HmdNoiseConfig) -> np.ndarray:
    """T_base_hmd moved by the configured calibration error: a rotation of `calibration_error_deg` about
    `pivot` and a shift of `calibration_error_m`, in seeded random directions (base frame)."""
    if cfg.calibration_error_m == 0 and cfg.calibration_error_deg == 0:
        return np.asarray(T_base_hmd, dtype=float).copy()
    delta = perturbation(np.random.default_rng(cfg.seed + 1), cfg.calibration_error_m, cfg.calibration_error_deg)
    pivot = np.asarray(cfg.pivot, dtype=float)
    about_pivot = make_T(np.eye(3), pivot) @ make_T(delta[:3, :3], np.zeros(3)) @ make_T(np.eye(3), -pivot)
    return make_T(np.eye(3), delta[:3, 3]) @ about_pivot @ T_base_hmd
