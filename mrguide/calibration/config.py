"""Calibration settings: dataclasses with defaults, loaded from `[calibration]` in a TOML file."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

from mrguide.config import ConfigError, Range, check_number, check_ranges, load_section

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
    #: black-square edge of single markers (fits a 5 cm cube face with a 5 mm quiet zone)
    marker_size_m: Annotated[float, Range(MIN_SIZE_M, MAX_SIZE_M, " m")] = 0.04
    corner_refinement: str = "edges"  # one of CORNER_REFINEMENTS; "edges" = OpenCV subpix, then straight-edge fits
    corner_window_px: Annotated[int, Range(1, 50, " px")] = 5  # half-size of the sub-pixel corner search window
    #: smallest marker perimeter as a fraction of the image's larger side
    min_marker_perimeter_rate: Annotated[float, Range(1e-4, 4.0)] = 0.02
    #: IPPE solutions whose error ratio (best/second) exceeds this are ambiguous
    ambiguity_ratio: Annotated[float, Range(1e-3, 1.0)] = 0.6

    def __post_init__(self) -> None:
        check_ranges(self, "calibration.detector")
        if self.corner_refinement not in CORNER_REFINEMENTS:
            raise ConfigError(
                f"calibration.detector.corner_refinement must be one of {CORNER_REFINEMENTS}, got {self.corner_refinement!r}"
            )


@dataclass(frozen=True)
class BoardConfig:
    """A printed calibration board: an ArUco grid board or a ChArUco board (same dictionary as the detector)."""

    kind: str = "grid"  # "grid" or "charuco"
    columns: Annotated[int, Range(1, 100)] = 5
    rows: Annotated[int, Range(1, 100)] = 4
    #: black-square edge of each board marker
    marker_size_m: Annotated[float, Range(MIN_SIZE_M, MAX_SIZE_M, " m")] = 0.05
    separation_m: float = 0.0125  # grid: gap between neighbouring markers
    #: charuco: chessboard square edge (> marker_size_m)
    square_size_m: Annotated[float, Range(MIN_SIZE_M, MAX_SIZE_M, " m")] = 0.07
    #: board marker ids are first_id, first_id + 1, ... (keeps them apart from object markers)
    first_id: Annotated[int, Range(0, MAX_MARKER_ID)] = 10
    margin_m: Annotated[float, Range(1e-4, 1.0, " m")] = 0.02  # white quiet zone printed around the board
    #: board thickness: its printed face lies this far above the table
    thickness_m: Annotated[float, Range(0.0, 0.1, " m")] = 0.003

    def __post_init__(self) -> None:
        if self.kind not in BOARD_KINDS:
            raise ConfigError(f"calibration.board.kind must be one of {BOARD_KINDS}, got {self.kind!r}")
        check_ranges(self, "calibration.board")
        if self.kind == "grid":
            check_number("calibration.board.separation_m", self.separation_m, 1e-4, MAX_SIZE_M, " m")
            return
        if not self.square_size_m > self.marker_size_m:
            raise ConfigError(
                f"calibration.board.square_size_m ({self.square_size_m}) must exceed marker_size_m ({self.marker_size_m})"
            )
        if min(self.columns, self.rows) < 2:
            raise ConfigError("calibration.board: a ChArUco board needs at least 2 columns and 2 rows")


@dataclass(frozen=True)
class MarkerPlacement:
    """A single marker at a known pose on the table: id, centre (m) and yaw (deg) in the robot base frame."""

    id: Annotated[int, Range(0, MAX_MARKER_ID)]
    xyz: tuple[float, float, float]
    yaw_deg: float = 0.0

    def __post_init__(self) -> None:
        check_ranges(self, "calibration.targets.markers")
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
    #: largest allowed residual of the touched corners against the board outline
    touch_tolerance_m: Annotated[float, Range(1e-5, 0.1, " m")] = 0.003
    markers: tuple[MarkerPlacement, ...] = ()  # single markers (size from the detector config)

    def __post_init__(self) -> None:
        check_points("calibration.targets.board_touched_corners", self.board_touched_corners)
        if self.board_touched_corners and len(self.board_touched_corners) not in (3, 4):
            raise ConfigError(
                f"calibration.targets.board_touched_corners needs 3 or 4 points, got {len(self.board_touched_corners)}"
            )
        if not self.use_board and not self.markers:
            raise ConfigError("calibration.targets: no targets (use_board = false and no markers)")
        check_ranges(self, "calibration.targets")


@dataclass(frozen=True)
class RegistrationConfig:
    """Registration of the HMD (or camera) frame to the robot base frame."""

    min_markers: Annotated[int, Range(1, 1000)] = 4  # target markers a frame must show to be used
    min_frames: Annotated[int, Range(1, 1000)] = 1  # usable frames required after outlier rejection
    #: frames whose estimate is farther than this from the median are rejected
    outlier_translation_m: Annotated[float, Range(1e-5, 1.0, " m")] = 0.01
    #: ... or whose rotation differs from the mean by more than this
    outlier_rotation_deg: Annotated[float, Range(1e-3, 180.0, " deg")] = 2.0
    #: a larger RMS residual is reported as a warning
    max_rms_residual_m: Annotated[float, Range(1e-6, 1.0, " m")] = 0.005

    def __post_init__(self) -> None:
        check_ranges(self, "calibration.registration")


@dataclass(frozen=True)
class HmdNoiseConfig:
    """Errors added to the HMD pipeline for sim-to-real studies (all zero: the pipeline as measured)."""

    tracking_noise_m: float = 0.0  # std per axis of the head-tracked camera position, per frame
    tracking_noise_deg: float = 0.0  # std per axis of the head-tracked camera rotation vector, per frame
    calibration_error_m: float = 0.0  # fixed offset (norm) added to T_base_hmd, random direction
    calibration_error_deg: float = 0.0  # fixed rotation (angle) added to T_base_hmd about `pivot`, random axis
    #: s from a frame's capture until its estimate reaches the runtime (a simulated HMD's own render time counts in it)
    latency_s: float = 0.0
    frame_drop: float = 0.0  # probability that a frame gives no estimate (motion blur, glare, a marker lost)
    pivot: tuple[float, float, float] = (
        0.475,
        0.1,
        0.0,
    )  # base point the rotation error turns about (workspace centre)
    seed: Annotated[int, Range(0, 2**32 - 1)] = 0

    def __post_init__(self) -> None:
        for name, high, unit in (
            ("tracking_noise_m", 0.1, " m"),
            ("tracking_noise_deg", 10.0, " deg"),
            ("calibration_error_m", 0.5, " m"),
            ("calibration_error_deg", 45.0, " deg"),
            ("latency_s", 2.0, " s"),
            ("frame_drop", 0.9, ""),
        ):
            check_number(f"calibration.hmd.{name}", getattr(self, name), 0.0, high, unit)
        check_ranges(self, "calibration.hmd")


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
