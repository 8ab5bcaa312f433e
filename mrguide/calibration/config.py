"""Calibration settings: dataclasses with defaults, loaded from `[calibration]` in a TOML file."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from mrguide.config import ConfigError, check_number, load_section

#: Corner refinement methods of the ArUco detector, by config name.
CORNER_REFINEMENTS = ("none", "subpix", "contour", "apriltag", "edges")
BOARD_KINDS = ("grid", "charuco")
#: Largest marker id accepted: OpenCV's largest predefined dictionary (DICT_ARUCO_ORIGINAL) has 1024 markers.
MAX_MARKER_ID = 1023
#: Size bounds of printed markers, squares and boards (m).
MIN_SIZE_M, MAX_SIZE_M = 1e-3, 2.0
#: Farthest a target may be from the robot base on any axis (m).
MAX_REACH_M = 5.0


def check_points(key: str, points: tuple[tuple[float, ...], ...], limit: float = MAX_REACH_M) -> None:
    """ConfigError unless every coordinate of every point is a finite number within +-`limit` (m).

    For tuples of points, which `mrguide.config.from_dict` does not look into."""
    for i, point in enumerate(points):
        for k, v in enumerate(point):
            check_number(f"{key}[{i}][{k}]", v, -limit, limit, " m")


@dataclass(frozen=True)
class DetectorConfig:
    """ArUco detection and single-marker pose."""

    dictionary: str = "DICT_4X4_50"  # an OpenCV predefined dictionary name
    marker_size_m: float = 0.04  # black-square edge of single markers (fits a 5 cm cube face with a 5 mm quiet zone)
    corner_refinement: str = "edges"  # one of CORNER_REFINEMENTS; "edges" = OpenCV subpix, then straight-edge fits
    corner_window_px: int = 5  # half-size of the sub-pixel corner search window
    min_marker_perimeter_rate: float = 0.02  # smallest marker perimeter as a fraction of the image's larger side
    ambiguity_ratio: float = 0.6  # IPPE solutions whose error ratio (best/second) exceeds this are ambiguous

    def __post_init__(self) -> None:
        check_number("calibration.detector.marker_size_m", self.marker_size_m, MIN_SIZE_M, MAX_SIZE_M, " m")
        check_number("calibration.detector.corner_window_px", self.corner_window_px, 1, 50, " px", integer=True)
        check_number("calibration.detector.min_marker_perimeter_rate", self.min_marker_perimeter_rate, 1e-4, 4.0)
        check_number("calibration.detector.ambiguity_ratio", self.ambiguity_ratio, 1e-3, 1.0)
        if self.corner_refinement not in CORNER_REFINEMENTS:
            raise ConfigError(
                f"calibration.detector.corner_refinement must be one of {CORNER_REFINEMENTS}, got {self.corner_refinement!r}"
            )


@dataclass(frozen=True)
class BoardConfig:
    """A printed calibration board: an ArUco grid board or a ChArUco board (same dictionary as the detector)."""

    kind: str = "grid"  # "grid" or "charuco"
    columns: int = 5
    rows: int = 4
    marker_size_m: float = 0.05  # black-square edge of each board marker
    separation_m: float = 0.0125  # grid: gap between neighbouring markers
    square_size_m: float = 0.07  # charuco: chessboard square edge (> marker_size_m)
    first_id: int = 10  # board marker ids are first_id, first_id + 1, ... (keeps them apart from object markers)
    margin_m: float = 0.02  # white quiet zone printed around the board
    thickness_m: float = 0.003  # board thickness: its printed face lies this far above the table

    def __post_init__(self) -> None:
        if self.kind not in BOARD_KINDS:
            raise ConfigError(f"calibration.board.kind must be one of {BOARD_KINDS}, got {self.kind!r}")
        check_number("calibration.board.columns", self.columns, 1, 100, integer=True)
        check_number("calibration.board.rows", self.rows, 1, 100, integer=True)
        check_number("calibration.board.marker_size_m", self.marker_size_m, MIN_SIZE_M, MAX_SIZE_M, " m")
        check_number("calibration.board.first_id", self.first_id, 0, MAX_MARKER_ID, integer=True)
        check_number("calibration.board.margin_m", self.margin_m, 1e-4, 1.0, " m")
        check_number("calibration.board.thickness_m", self.thickness_m, 0.0, 0.1, " m")
        if self.kind == "grid":
            check_number("calibration.board.separation_m", self.separation_m, 1e-4, MAX_SIZE_M, " m")
            return
        check_number("calibration.board.square_size_m", self.square_size_m, MIN_SIZE_M, MAX_SIZE_M, " m")
        if not self.square_size_m > self.marker_size_m:
            raise ConfigError(
                f"calibration.board.square_size_m ({self.square_size_m}) must exceed marker_size_m ({self.marker_size_m})"
            )
        if min(self.columns, self.rows) < 2:
            raise ConfigError("calibration.board: a ChArUco board needs at least 2 columns and 2 rows")


@dataclass(frozen=True)
class MarkerPlacement:
    """A single marker at a known pose on the table: id, centre (m) and yaw (deg) in the robot base frame."""

    id: int
    xyz: tuple[float, float, float]
    yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        check_number("calibration.targets.markers.id", self.id, 0, MAX_MARKER_ID, integer=True)
        check_points(f"calibration.targets.markers (id {self.id}).xyz", (self.xyz,))
        check_number(f"calibration.targets.markers (id {self.id}).yaw_deg", self.yaw_deg, -360.0, 360.0, " deg")


@dataclass(frozen=True)
class TargetsConfig:
    """Where the calibration targets are in the robot base frame.

    The board is placed by `board_xyz`/`board_yaw_deg` (its origin, the outer corner of marker `first_id`,
    on the printed face), or, when `board_touched_corners` holds 3 or 4 points, by the board outline
    corners touched with the TCP, in the order origin, +x corner, opposite corner, +y corner.
    """

    use_board: bool = True
    board_xyz: tuple[float, float, float] = (0.33, 0.25, 0.003)
    board_yaw_deg: float = 0.0
    board_touched_corners: tuple[tuple[float, float, float], ...] = ()
    touch_tolerance_m: float = 0.003  # largest allowed residual of the touched corners against the board outline
    markers: tuple[MarkerPlacement, ...] = ()  # single markers (size from the detector config)

    def __post_init__(self) -> None:
        check_points("calibration.targets.board_touched_corners", self.board_touched_corners)
        if self.board_touched_corners and len(self.board_touched_corners) not in (3, 4):
            raise ConfigError(
                f"calibration.targets.board_touched_corners needs 3 or 4 points, got {len(self.board_touched_corners)}"
            )
        if not self.use_board and not self.markers:
            raise ConfigError("calibration.targets: no targets (use_board = false and no markers)")
        check_number("calibration.targets.touch_tolerance_m", self.touch_tolerance_m, 1e-5, 0.1, " m")


@dataclass(frozen=True)
class RegistrationConfig:
    """Registration of the HMD (or camera) frame to the robot base frame."""

    min_markers: int = 4  # target markers a frame must show to be used
    min_frames: int = 1  # usable frames required after outlier rejection
    outlier_translation_m: float = 0.01  # frames whose estimate is farther than this from the median are rejected
    outlier_rotation_deg: float = 2.0  # ... or whose rotation differs from the mean by more than this
    max_rms_residual_m: float = 0.005  # a larger RMS residual is reported as a warning

    def __post_init__(self) -> None:
        check_number("calibration.registration.min_markers", self.min_markers, 1, 1000, integer=True)
        check_number("calibration.registration.min_frames", self.min_frames, 1, 1000, integer=True)
        check_number("calibration.registration.outlier_translation_m", self.outlier_translation_m, 1e-5, 1.0, " m")
        check_number("calibration.registration.outlier_rotation_deg", self.outlier_rotation_deg, 1e-3, 180.0, " deg")
        check_number("calibration.registration.max_rms_residual_m", self.max_rms_residual_m, 1e-6, 1.0, " m")


@dataclass(frozen=True)
class HmdNoiseConfig:
    """Errors added to the HMD pipeline for sim-to-real studies (all zero: the pipeline as measured)."""

    tracking_noise_m: float = 0.0  # std per axis of the head-tracked camera position, per frame
    tracking_noise_deg: float = 0.0  # std per axis of the head-tracked camera rotation vector, per frame
    calibration_error_m: float = 0.0  # fixed offset (norm) added to T_base_hmd, random direction
    calibration_error_deg: float = 0.0  # fixed rotation (angle) added to T_base_hmd about `pivot`, random axis
    pivot: tuple[float, float, float] = (
        0.475,
        0.1,
        0.0,
    )  # base point the rotation error turns about (workspace centre)
    seed: int = 0

    def __post_init__(self) -> None:
        for name, high, unit in (
            ("tracking_noise_m", 0.1, " m"),
            ("tracking_noise_deg", 10.0, " deg"),
            ("calibration_error_m", 0.5, " m"),
            ("calibration_error_deg", 45.0, " deg"),
        ):
            check_number(f"calibration.hmd.{name}", getattr(self, name), 0.0, high, unit)
        check_number("calibration.hmd.seed", self.seed, 0, 2**32 - 1, integer=True)


@dataclass(frozen=True)
class CalibrationConfig:
    """`[calibration]`: detector, board, target placement, registration and HMD noise."""

    detector: DetectorConfig = field(default_factory=DetectorConfig)
    board: BoardConfig = field(default_factory=BoardConfig)
    targets: TargetsConfig = field(default_factory=TargetsConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    hmd: HmdNoiseConfig = field(default_factory=HmdNoiseConfig)


def load_calibration_config(path: str | Path | None) -> CalibrationConfig:
    """`[calibration]` of a TOML file; defaults when `path` is None."""
    return load_section(CalibrationConfig, path, "calibration")
