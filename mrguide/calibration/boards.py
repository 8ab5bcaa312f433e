"""Calibration boards (ArUco grid or ChArUco), their geometry, and printable images of boards and markers.

Board frame (OpenCV >= 4.6): origin at the outer corner of the first marker (grid) or of the chessboard
(ChArUco), x along the columns, y along the rows (down the printed image), z = x × y into the board.
A board lying face up on the table therefore has its z axis pointing down.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import cv2
import numpy as np

from mrguide.calibration.config import BoardConfig
from mrguide.calibration.errors import CalibrationError
from mrguide.calibration.se3 import make_T, rotation_about

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Board:
    """An OpenCV board together with the config it was built from."""

    cfg: BoardConfig
    board: cv2.aruco.Board

    @property
    def ids(self) -> np.ndarray:
        return np.asarray(self.board.getIds()).reshape(-1).astype(int)  # an (n, 1) array (typed as a sequence)

    @property
    def charuco(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV board of a board of kind "charuco" (TypeError for a grid)."""
        if not isinstance(self.board, cv2.aruco.CharucoBoard):
            raise TypeError(f"calibration.board: a {self.cfg.kind!r} board is no ChArUco board")
        return self.board

    @property
    def size_m(self) -> tuple[float, float]:
        """Extent (width, height) of the board pattern, without the margin."""
        w, h, _ = self.board.getRightBottomCorner()
        return float(w), float(h)

    def marker_corners(self) -> dict[int, np.ndarray]:
        """Board-frame corners (4, 3) of each marker, by id, clockwise from the top-left as detected."""
        return {int(i): np.asarray(p, dtype=float).reshape(4, 3) for i, p in zip(self.ids, self.board.getObjPoints())}

    def outline(self) -> np.ndarray:
        """Board-frame corners (4, 3) of the pattern: origin, +x corner, opposite corner, +y corner."""
        w, h = self.size_m
        return np.array([[0.0, 0.0, 0.0], [w, 0.0, 0.0], [w, h, 0.0], [0.0, h, 0.0]])


def make_board(cfg: BoardConfig, dictionary: cv2.aruco.Dictionary) -> Board:
    """The grid or ChArUco board described by `cfg`, with marker ids from `cfg.first_id` on."""
    board: cv2.aruco.Board
    if cfg.kind == "grid":
        n = cfg.columns * cfg.rows
        ids = np.arange(cfg.first_id, cfg.first_id + n, dtype=np.int32)
        _check_ids(ids, dictionary)
        board = cv2.aruco.GridBoard((cfg.columns, cfg.rows), cfg.marker_size_m, cfg.separation_m, dictionary, ids)
    else:
        n = (cfg.columns * cfg.rows) // 2
        ids = np.arange(cfg.first_id, cfg.first_id + n, dtype=np.int32)
        _check_ids(ids, dictionary)
        board = cv2.aruco.CharucoBoard((cfg.columns, cfg.rows), cfg.square_size_m, cfg.marker_size_m, dictionary, ids)
    return Board(cfg, board)


def _check_ids(ids: np.ndarray, dictionary: cv2.aruco.Dictionary) -> None:
    size = dictionary.bytesList.shape[0]
    if ids.max() >= size:
        raise CalibrationError(
            f"calibration.board: ids {ids.min()}..{ids.max()} do not fit the dictionary's {size} markers; "
            "lower first_id, shrink the board or use a larger dictionary"
        )


def board_pose_on_table(xyz: tuple[float, float, float], yaw_deg: float) -> np.ndarray:
    """T_base_board of a board lying face up with its origin at `xyz` and its x axis at `yaw_deg` about base z."""
    R_yaw = rotation_about(np.array([0.0, 0.0, 1.0]), np.radians(yaw_deg))
    flip = np.diag([1.0, -1.0, -1.0])  # board y along base -y, board z into the table
    return make_T(R_yaw @ flip, xyz)


def marker_pose_on_table(xyz: tuple[float, float, float], yaw_deg: float) -> np.ndarray:
    """T_base_marker of a single marker lying face up (marker z up) centred at `xyz`, x axis at `yaw_deg`."""
    return make_T(rotation_about(np.array([0.0, 0.0, 1.0]), np.radians(yaw_deg)), xyz)


def single_marker_corners(size_m: float) -> np.ndarray:
    """Marker-frame corners (4, 3) in detection order; the order `SOLVEPNP_IPPE_SQUARE` requires."""
    s = size_m / 2.0
    return np.array([[-s, s, 0.0], [s, s, 0.0], [s, -s, 0.0], [-s, -s, 0.0]])


def printable_marker(
    dictionary: cv2.aruco.Dictionary, marker_id: int, size_m: float, quiet_zone_m: float, px_per_m: float
) -> np.ndarray:
    """uint8 image of one marker with a white quiet zone, `px_per_m` pixels per metre.

    The image spans the marker square grown by `quiet_zone_m` on every side; its top-left pixel edge is the
    marker-frame point (-size/2 - quiet, size/2 + quiet).
    """
    if not 0 <= marker_id < dictionary.bytesList.shape[0]:
        raise CalibrationError(
            f"marker id {marker_id} is not in the dictionary (0..{dictionary.bytesList.shape[0] - 1})"
        )
    side = round(size_m * px_per_m)
    pad = round(quiet_zone_m * px_per_m)
    if side < dictionary.markerSize + 2 or pad < 1:
        raise CalibrationError(f"printable_marker: {px_per_m} px/m is too coarse for a {size_m} m marker")
    img = cv2.aruco.generateImageMarker(dictionary, marker_id, side, borderBits=1)
    return cv2.copyMakeBorder(img, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=255)


def printable_board(board: Board, px_per_m: float) -> np.ndarray:
    """uint8 image of the board with its white margin; the top-left pixel edge is board point (-margin, -margin).

    OpenCV rounds every marker and square to whole pixels, so choose `px_per_m` to make them whole
    (e.g. 4000 px/m for 5 cm markers 12.5 mm apart): otherwise the print is off by up to half a pixel per
    element, and a twin board made from it shows sub-millimetre pose errors that are not the detector's.
    """
    c = board.cfg
    lengths = (c.marker_size_m, c.margin_m, c.separation_m if c.kind == "grid" else c.square_size_m)
    off = max(abs(v * px_per_m - round(v * px_per_m)) for v in lengths)
    if off > 0.01:
        log.warning(
            "printable_board: at %g px/m the board's elements are not whole pixels (off by %.2f px)", px_per_m, off
        )
    w, h = board.size_m
    margin = round(board.cfg.margin_m * px_per_m)
    size = (round(w * px_per_m) + 2 * margin, round(h * px_per_m) + 2 * margin)
    return board.board.generateImage(size, marginSize=margin, borderBits=1)
