"""Rigid fits, multi-frame registration with outlier rejection, and the HMD error models (no rendering)."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.calibration.config import HmdNoiseConfig, RegistrationConfig
from mrguide.calibration.errors import CalibrationError, NotEnoughMarkersError
from mrguide.calibration.hmd import HmdFrame, with_calibration_error, with_tracking_noise
from mrguide.calibration.registration import Correspondences, fit_rigid, register
from mrguide.calibration.se3 import apply, invert, make_T, perturbation, rotation_about, rotation_angle_deg

RNG = np.random.default_rng(7)
T_TRUE = make_T(rotation_about([0.3, -0.5, 1.0], 2.1), [1.2, 0.3, 0.5])  # T_base_hmd


def _frame(label: str, n_markers: int = 6, noise: float = 0.0, T: np.ndarray = T_TRUE) -> Correspondences:
    base = RNG.uniform([0.3, -0.2, 0.0], [0.65, 0.4, 0.0], size=(4 * n_markers, 3))
    hmd = apply(invert(T), base) + RNG.normal(0.0, noise, base.shape)
    return Correspondences(label, hmd, base, n_markers)


def test_fit_rigid_recovers_transform_and_residuals():
    src = RNG.uniform(-0.3, 0.3, size=(40, 3))
    dst = apply(T_TRUE, src) + RNG.normal(0.0, 0.001, src.shape)
    fit = fit_rigid(src, dst)
    assert np.linalg.norm(fit.T_dst_src[:3, 3] - T_TRUE[:3, 3]) < 1e-3
    assert rotation_angle_deg(fit.T_dst_src[:3, :3], T_TRUE[:3, :3]) < 0.2
    assert 0.001 < fit.rms_m < 0.002  # ~sqrt(3) * 1 mm minus the fitted degrees of freedom


def test_fit_rigid_refuses_degenerate_input():
    with pytest.raises(NotEnoughMarkersError, match="at least 3"):
        fit_rigid(np.zeros((2, 3)), np.zeros((2, 3)))
    line = np.outer(np.linspace(0, 1, 5), [1.0, 2.0, 3.0])
    with pytest.raises(CalibrationError, match="one line"):
        fit_rigid(line, line)


def test_register_rejects_outlier_frame_and_thin_frames():
    frames = [_frame(f"f{i}", noise=0.0005) for i in range(5)]
    frames.append(_frame("bad", T=perturbation(RNG, 0.03, 3.0) @ T_TRUE))
    frames.append(_frame("thin", n_markers=2))
    reg = register(frames, RegistrationConfig(min_markers=4))
    assert set(reg.frames_rejected) == {"bad", "thin"}
    assert "outlier" in reg.frames_rejected["bad"] and "2 target markers" in reg.frames_rejected["thin"]
    assert np.linalg.norm(reg.T_base_hmd[:3, 3] - T_TRUE[:3, 3]) < 0.001
    assert reg.rms_m < 0.0015


def test_register_with_too_few_markers_raises_instead_of_guessing():
    with pytest.raises(
        NotEnoughMarkersError, match=r"0 usable frames, 1 required.*2 target markers usable, 4 required"
    ):
        register([_frame("only", n_markers=2)], RegistrationConfig(min_markers=4))


def test_calibration_error_has_configured_size_at_pivot():
    cfg = HmdNoiseConfig(calibration_error_m=0.01, calibration_error_deg=2.0, pivot=(0.5, 0.1, 0.0))
    T_err = with_calibration_error(T_TRUE, cfg)
    pivot_hmd = apply(invert(T_TRUE), np.array([0.5, 0.1, 0.0]))
    assert np.linalg.norm(apply(T_err, pivot_hmd) - [0.5, 0.1, 0.0]) == pytest.approx(0.01, abs=1e-9)
    assert rotation_angle_deg(T_err[:3, :3], T_TRUE[:3, :3]) == pytest.approx(2.0, abs=1e-6)
    assert np.array_equal(with_calibration_error(T_TRUE, HmdNoiseConfig()), T_TRUE)


def test_tracking_noise_statistics():
    frames = with_tracking_noise(
        lambda: HmdFrame(np.zeros((2, 2), np.uint8), np.eye(4)),
        HmdNoiseConfig(tracking_noise_m=0.002, tracking_noise_deg=0.5, seed=3),
    )
    poses = [frames().T_hmd_cam for _ in range(2000)]
    t = np.array([p[:3, 3] for p in poses])
    angles = np.array([rotation_angle_deg(np.eye(3), p[:3, :3]) for p in poses])
    assert np.std(t, axis=0) == pytest.approx([0.002] * 3, rel=0.1)
    assert np.sqrt(np.mean(angles**2)) == pytest.approx(0.5 * np.sqrt(3), rel=0.1)  # 3 axes of 0.5 deg
