"""ArUco marker detection with OpenCV's `ArucoDetector`: dictionary lookup, corner refinement, results."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

from mrguide.calibration.camera_model import CameraModel
from mrguide.calibration.config import DetectorConfig
from mrguide.calibration.corner_refinement import refine_marker_corners
from mrguide.calibration.errors import CalibrationError

log = logging.getLogger(__name__)

_REFINEMENT = {
    "none": cv2.aruco.CORNER_REFINE_NONE,
    "edges": cv2.aruco.CORNER_REFINE_SUBPIX,  # then refine_marker_corners
    "subpix": cv2.aruco.CORNER_REFINE_SUBPIX,
    "contour": cv2.aruco.CORNER_REFINE_CONTOUR,
    "apriltag": cv2.aruco.CORNER_REFINE_APRILTAG,
}


def dictionary_names() -> list[str]:
    """Names of OpenCV's predefined ArUco/AprilTag dictionaries (e.g. 'DICT_4X4_50')."""
    return sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and n == n.upper())


def canonical_dictionary_name(name: str) -> str:
    """'DICT_4X4_50' for '4x4_50', 'dict_4x4_50', ...; CalibrationError naming the known ones otherwise."""
    key = name.strip().upper()
    key = key if key.startswith("DICT_") else f"DICT_{key}"
    if key not in dictionary_names():
        raise CalibrationError(f"unknown ArUco dictionary {name!r}; known: {', '.join(dictionary_names())}")
    return key


def get_dictionary(name: str) -> cv2.aruco.Dictionary:
    """The predefined dictionary called `name` ('DICT_4X4_50'; the 'DICT_' prefix may be left out)."""
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, canonical_dictionary_name(name)))


def to_gray(image: np.ndarray, where: str = "image") -> np.ndarray:
    """A uint8 grayscale view of a gray (H, W) or RGB (H, W, 3) image."""
    img = np.asarray(image)
    if img.dtype != np.uint8:
        raise CalibrationError(f"{where}: expected a uint8 image, got dtype {img.dtype}")
    if img.ndim == 2:
        return img
    if img.ndim == 3 and img.shape[2] == 3:
        return cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)
    raise CalibrationError(f"{where}: expected a gray (H, W) or RGB (H, W, 3) image, got shape {img.shape}")


@dataclass(frozen=True)
class Detections:
    """Detected markers: corners (N, 4, 2) in px (clockwise from the marker's top-left) and ids (N,)."""

    corners: np.ndarray
    ids: np.ndarray
    rejected: tuple[np.ndarray, ...] = ()  # candidate quads whose code did not decode (for board refinement)

    def __len__(self) -> int:
        return len(self.ids)

    def corners_of(self, marker_id: int) -> np.ndarray | None:
        """Corners (4, 2) of `marker_id`, or None if it was not detected (or detected twice, ambiguously)."""
        hits = np.flatnonzero(self.ids == marker_id)
        if len(hits) != 1:
            if len(hits) > 1:
                log.warning("marker %d detected %d times; ignoring it", marker_id, len(hits))
            return None
        return self.corners[hits[0]]

    def only(self, ids: set[int] | np.ndarray) -> Detections:
        """The detections whose id is in `ids`."""
        keep = np.isin(self.ids, list(ids))
        return Detections(self.corners[keep], self.ids[keep], self.rejected)

    def as_opencv(self) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
        """Corners and ids in the layout OpenCV's aruco functions take."""
        corners = tuple(c.reshape(1, 4, 2).astype(np.float32) for c in self.corners)
        return corners, self.ids.reshape(-1, 1).astype(np.int32)

    @classmethod
    def from_opencv(cls, corners, ids, rejected=()) -> Detections:
        if ids is None or len(ids) == 0:
            return cls(np.zeros((0, 4, 2)), np.zeros(0, dtype=int), tuple(rejected))
        c = np.asarray(corners, dtype=float).reshape(-1, 4, 2)
        return cls(c, np.asarray(ids, dtype=int).reshape(-1), tuple(rejected))


class MarkerDetector:
    """Finds markers of one dictionary in gray or RGB uint8 images."""

    def __init__(self, cfg: DetectorConfig = DetectorConfig()):
        self.cfg = cfg
        self.dictionary = get_dictionary(cfg.dictionary)
        params = cv2.aruco.DetectorParameters()
        params.cornerRefinementMethod = _REFINEMENT[cfg.corner_refinement]
        params.cornerRefinementWinSize = cfg.corner_window_px
        params.minMarkerPerimeterRate = cfg.min_marker_perimeter_rate
        self.params = params
        self.detector = cv2.aruco.ArucoDetector(self.dictionary, params)

    @property
    def marker_size_m(self) -> float:
        return self.cfg.marker_size_m

    def detect(self, image: np.ndarray, where: str = "image", camera: CameraModel | None = None) -> Detections:
        """All markers of the dictionary in `image`; `camera` lets edge refinement undo lens distortion."""
        gray = to_gray(image, where)
        corners, ids, rejected = self.detector.detectMarkers(gray)
        det = Detections.from_opencv(corners, ids, rejected)
        if self.cfg.corner_refinement == "edges" and len(det):
            bits = self.dictionary.markerSize + 2
            refined = np.stack([refine_marker_corners(gray, c, bits, camera) for c in det.corners])
            det = Detections(refined, det.ids, det.rejected)
        log.debug("%s: %d markers %s", where, len(det), det.ids.tolist())
        return det
