"""Camera intrinsics for pose estimation: pinhole matrix, distortion, image size, loaded from a file."""

from __future__ import annotations

import json
import math
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from mrguide.calibration.errors import CalibrationError

#: Largest image side (px) accepted in intrinsics (16K).
MAX_IMAGE_SIDE = 16384


@dataclass(frozen=True)
class CameraModel:
    """Pinhole intrinsics (px) with OpenCV distortion coefficients, for images of `width` x `height`."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if not all(
            isinstance(v, int) and not isinstance(v, bool) and 0 < v <= MAX_IMAGE_SIDE
            for v in (self.width, self.height)
        ):
            raise CalibrationError(
                f"camera intrinsics: width and height must be whole pixels in [1, {MAX_IMAGE_SIDE}], "
                f"got {self.width!r} x {self.height!r}"
            )
        if not np.all(np.isfinite([self.fx, self.fy, self.cx, self.cy, *self.dist])):
            raise CalibrationError(f"camera intrinsics: non-finite values in {self}")
        if self.fx <= 0 or self.fy <= 0:
            raise CalibrationError(f"camera intrinsics: focal lengths must be positive, got fx {self.fx}, fy {self.fy}")
        if len(self.dist) not in (0, 4, 5, 8, 12, 14):
            raise CalibrationError(
                f"camera intrinsics: {len(self.dist)} distortion coefficients; OpenCV takes 4, 5, 8, 12 or 14"
            )

    @property
    def K(self) -> np.ndarray:
        """3x3 camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist_coeffs(self) -> np.ndarray:
        """Distortion coefficients as OpenCV takes them (zeros when there are none)."""
        return np.asarray(self.dist, dtype=float) if self.dist else np.zeros(5)

    @classmethod
    def from_pinhole(cls, intrinsics: Any) -> CameraModel:
        """From any object with width, height, fx, fy, cx, cy (e.g. the twin camera's `Intrinsics`)."""
        k = intrinsics
        return cls(int(k.width), int(k.height), float(k.fx), float(k.fy), float(k.cx), float(k.cy))

    def check_image(self, image: np.ndarray, where: str = "image") -> None:
        """Raise CalibrationError when the image size differs from the intrinsics' size."""
        h, w = image.shape[:2]
        if (w, h) != (self.width, self.height):
            raise CalibrationError(
                f"{where}: image is {w}x{h} but the intrinsics are for {self.width}x{self.height}; "
                "use the intrinsics of the camera mode that took the image"
            )

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Pixel coordinates (N, 2) of camera-frame points (N, 3), with distortion."""
        pts = np.ascontiguousarray(np.atleast_2d(points_cam), dtype=float)
        uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), self.K, self.dist_coeffs)
        return uv.reshape(-1, 2)

    def to_dict(self) -> dict[str, Any]:
        return {
            "width": self.width,
            "height": self.height,
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "dist": list(self.dist),
        }


def load_camera_model(path: str | Path) -> CameraModel:
    """Read intrinsics from JSON, TOML or an OpenCV YAML/XML file.

    JSON/TOML: `width`, `height` and either `fx, fy, cx, cy` or `camera_matrix` (3x3), optional `dist`
    (or `dist_coeffs`). OpenCV files: `image_width`, `image_height`, `camera_matrix`, `distortion_coefficients`.
    """
    path = Path(path)
    if not path.is_file():
        raise CalibrationError(f"intrinsics file not found: {path}")
    suffix = path.suffix.lower()
    try:
        if suffix == ".json":
            data = json.loads(path.read_text())
        elif suffix == ".toml":
            data = tomllib.loads(path.read_text())
        elif suffix in (".yaml", ".yml", ".xml"):
            data = _read_opencv_storage(path)
        else:
            raise CalibrationError(f"{path}: unknown intrinsics format {suffix!r} (use .json, .toml, .yaml or .xml)")
    except (json.JSONDecodeError, tomllib.TOMLDecodeError, UnicodeDecodeError, cv2.error, SystemError) as exc:
        # OpenCV's FileStorage raises SystemError on a corrupt YAML/XML file, the cv2.error inside says why
        cause = exc.__context__ if isinstance(exc, SystemError) and exc.__context__ else exc
        raise CalibrationError(f"{path}: cannot parse intrinsics: {' '.join(str(cause).split())}") from exc
    return camera_from_dict(data, str(path))


def _read_opencv_storage(path: Path) -> dict[str, Any]:
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    if not fs.isOpened():
        raise CalibrationError(f"{path}: OpenCV cannot open it as a FileStorage file")
    try:
        K, dist = fs.getNode("camera_matrix").mat(), fs.getNode("distortion_coefficients").mat()
        return {
            "width": fs.getNode("image_width").real(),
            "height": fs.getNode("image_height").real(),
            "camera_matrix": None if K is None else K.tolist(),
            "dist": [] if dist is None else dist.ravel().tolist(),
        }
    finally:
        fs.release()


def camera_from_dict(data: Any, where: str) -> CameraModel:
    """Intrinsics from a parsed file (or a calibration file's "camera"); CalibrationError naming `where`."""
    if not isinstance(data, dict):
        raise CalibrationError(f"{where}: intrinsics must be a table/object, got {type(data).__name__}")
    try:
        width, height = _pixels(data["width"], "width", where), _pixels(data["height"], "height", where)
        if "camera_matrix" in data and data["camera_matrix"] is not None:
            K = np.asarray(data["camera_matrix"], dtype=float)
            if K.shape != (3, 3):
                raise CalibrationError(f"{where}: camera_matrix must be 3x3, got shape {K.shape}")
            fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
        else:
            fx, fy, cx, cy = (float(data[k]) for k in ("fx", "fy", "cx", "cy"))
        dist_coeffs = data["dist"] if "dist" in data else data.get("dist_coeffs", ())
        dist = tuple(float(d) for d in dist_coeffs)
    except CalibrationError:
        raise
    except KeyError as exc:
        raise CalibrationError(f"{where}: missing intrinsics key {exc.args[0]!r}") from exc
    except (TypeError, ValueError) as exc:
        raise CalibrationError(f"{where}: bad intrinsics value: {exc}") from exc
    if not np.all(np.isfinite([fx, fy, cx, cy, *dist])):
        raise CalibrationError(f"{where}: intrinsics contain non-finite values")
    try:
        return CameraModel(width, height, float(fx), float(fy), float(cx), float(cy), dist)
    except CalibrationError as exc:
        raise CalibrationError(f"{where}: {exc}") from exc


def _pixels(value: Any, key: str, where: str) -> int:
    """A whole number of pixels (an integral float from OpenCV's FileStorage is fine; 640.5 or inf is not)."""
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, float))
        or not math.isfinite(value)
        or value != int(value)
    ):
        raise CalibrationError(f"{where}: intrinsics {key} = {value!r}: expected a whole number of pixels")
    return int(value)
