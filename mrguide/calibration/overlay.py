"""Pictures for a person to check a calibration: detected markers, ids and pose axes drawn on the images."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import cv2
import numpy as np

from mrguide.calibration.camera_model import CameraModel
from mrguide.calibration.detection import Detections
from mrguide.calibration.pose import PoseEstimate
from mrguide.calibration.se3 import to_rvec_tvec


def draw_overlay(
    image: np.ndarray,
    detections: Detections,
    poses: Sequence[tuple[PoseEstimate, float]],
    camera: CameraModel,
    caption: str = "",
) -> np.ndarray:
    """BGR copy of an RGB/gray image with marker outlines and ids, and x/y/z axes (red/green/blue) per pose."""
    out = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_RGB2BGR)
    if len(detections):
        corners, ids = detections.as_opencv()
        cv2.aruco.drawDetectedMarkers(out, corners, ids, borderColor=(0, 255, 255))
    for pose, length in poses:
        rvec, tvec = to_rvec_tvec(pose.T_cam_target)
        cv2.drawFrameAxes(out, camera.K, camera.dist_coeffs, rvec, tvec, length, 2)
    if caption:
        cv2.putText(out, caption, (10, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 0, 0), 4, cv2.LINE_AA)
        cv2.putText(out, caption, (10, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (255, 255, 255), 2, cv2.LINE_AA)
    return out


def mosaic(images: Sequence[np.ndarray], max_width: int = 1920) -> np.ndarray:
    """BGR images side by side (two per row, scaled to fit `max_width`) as one BGR image."""
    cols = 1 if len(images) == 1 else 2
    h, w = images[0].shape[:2]
    scale = min(1.0, max_width / (cols * w))
    size = (int(w * scale), int(h * scale))
    tiles = [cv2.resize(im, size, interpolation=cv2.INTER_AREA) for im in images]
    tiles += [np.zeros_like(tiles[0])] * (-len(tiles) % cols)
    return np.vstack([np.hstack(tiles[i : i + cols]) for i in range(0, len(tiles), cols)])


def encode_image(image: np.ndarray, path: str | Path) -> bytes:
    """The bytes of `image` in the format of `path`'s extension (checked beforehand with `can_write_image`)."""
    ok, data = cv2.imencode(Path(path).suffix, image)
    if not ok:
        raise ValueError(f"OpenCV could not encode an image as {Path(path).suffix}")
    return data.tobytes()


def can_write_image(path: str | Path) -> bool:
    """Whether OpenCV has an encoder for `path`'s extension."""
    return cv2.haveImageWriter(str(path))
