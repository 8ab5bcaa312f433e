"""Image-space degradations for synthetic tests and benchmarks: sensor noise, defocus/motion blur, occlusion."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from mrguide.calibration.errors import CalibrationError


@dataclass(frozen=True)
class Degradation:
    """What to do to a clean render; all zero leaves it unchanged."""

    noise_std: float = 0.0  # grey levels, additive Gaussian per pixel and channel
    blur_sigma_px: float = 0.0  # Gaussian blur (defocus / motion smear)
    occlusion: float = 0.0  # fraction of the region's width covered by an occluder from the left

    def __post_init__(self) -> None:
        if self.noise_std < 0 or self.blur_sigma_px < 0 or not 0 <= self.occlusion <= 1:
            raise CalibrationError(f"degradation: noise and blur must be >= 0 and occlusion in [0, 1], got {self}")


def add_noise(image: np.ndarray, std: float, rng: np.random.Generator) -> np.ndarray:
    noisy = image.astype(np.float32) + rng.normal(0.0, std, image.shape).astype(np.float32)
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def blur(image: np.ndarray, sigma_px: float) -> np.ndarray:
    return cv2.GaussianBlur(image, (0, 0), sigmaX=sigma_px)


def occlude(image: np.ndarray, region: np.ndarray, fraction: float, grey: int = 90) -> np.ndarray:
    """Cover the left `fraction` of the bounding box of `region` (pixel points (N, 2)) with a flat occluder."""
    out = image.copy()
    x0, y0 = np.floor(region.min(axis=0)).astype(int)
    x1, y1 = np.ceil(region.max(axis=0)).astype(int)
    xe = x0 + round(fraction * (x1 - x0))
    h, w = image.shape[:2]
    out[max(y0, 0) : min(y1 + 1, h), max(x0, 0) : min(xe, w)] = grey
    return out


def degrade(
    image: np.ndarray, d: Degradation, rng: np.random.Generator, region: np.ndarray | None = None
) -> np.ndarray:
    """Occlusion (of `region`, default the whole image), then blur, then noise."""
    out = image
    if d.occlusion > 0:
        h, w = image.shape[:2]
        out = occlude(out, np.array([[0, 0], [w - 1, h - 1]]) if region is None else region, d.occlusion)
    if d.blur_sigma_px > 0:
        out = blur(out, d.blur_sigma_px)
    if d.noise_std > 0:
        out = add_noise(out, d.noise_std, rng)
    return out
