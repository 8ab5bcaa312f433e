"""Calibration settings: dataclasses with defaults, loaded from `[calibration]` in a TOML file."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from mrguide.config import ConfigError, load_section

#: Corner refinement methods of the ArUco detector, by config name.
CORNER_REFINEMENTS = ("none", "subpix", "contour", "apriltag", "edges")
BOARD_KINDS = ("grid", "charuco")


def _positive(where: str, **values: float) -> None:
    for name, value in values.items():
        if not value > 0:
            raise ConfigError(f"{where}.{name} must be > 0, got {value}")


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
        _positive("calibration.detector", marker_size_m=self.marker_size_m, corner_window_px=self.corner_window_px,
                  min_marker_perimeter_rate=self.min_marker_perimeter_rate, ambiguity_ratio=self.ambiguity_ratio)
        if self.corner_refinement not in CORNER_REFINEMENTS:
            raise ConfigError(
                f"calibration.detector.corner_refinement must be one of {CORNER_REFINEMENTS}, got {self.corner_refinement!r}"
            )
        if self.ambiguity_ratio > 1:
            raise ConfigError(f"calibration.detector.ambiguity_ratio must be <= 1, got {self.ambiguity_ratio}")


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
        _positive("calibration.board", columns=self.columns, rows=self.rows, marker_size_m=self.marker_size_m,
                  margin_m=self.margin_m)
        if self.first_id < 0:
            raise ConfigError(f"calibration.board.first_id must be >= 0, got {self.first_id}")
        if self.thickness_m < 0:
            raise ConfigError(f"calibration.board.thickness_m must be >= 0, got {self.thickness_m}")
        if self.kind == "grid":
            _positive("calibration.board", separation_m=self.separation_m)
        elif not self.square_size_m > self.marker_size_m:
            raise ConfigError(
                f"calibration.board.square_size_m ({self.square_size_m}) must exceed marker_size_m ({self.marker_size_m})"
            )
        if self.kind == "charuco" and min(self.columns, self.rows) < 2:
            raise ConfigError("calibration.board: a ChArUco board needs at least 2 columns and 2 rows")


@dataclass(frozen=True)
class MarkerPlacement:
    """A single marker at a known pose on the table: id, centre (m) and yaw (deg) in the robot base frame."""

    id: int
    xyz: tuple[float, float, float]
    yaw_deg: float = 0.0


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
        if self.board_touched_corners and len(self.board_touched_corners) not in (3, 4):
            raise ConfigError(
                f"calibration.targets.board_touched_corners needs 3 or 4 points, got {len(self.board_touched_corners)}"
            )
        if not self.use_board and not self.markers:
            raise ConfigError("calibration.targets: no targets (use_board = false and no markers)")
        _positive("calibration.targets", touch_tolerance_m=self.touch_tolerance_m)


@dataclass(frozen=True)
class RegistrationConfig:
    """Registration of the HMD (or camera) frame to the robot base frame."""

    min_markers: int = 4  # target markers a frame must show to be used
    min_frames: int = 1  # usable frames required after outlier rejection
    outlier_translation_m: float = 0.01  # frames whose estimate is farther than this from the median are rejected
    outlier_rotation_deg: float = 2.0  # ... or whose rotation differs from the mean by more than this
    max_rms_residual_m: float = 0.005  # a larger RMS residual is reported as a warning

    def __post_init__(self) -> None:
        if self.min_markers < 1 or self.min_frames < 1:
            raise ConfigError("calibration.registration: min_markers and min_frames must be >= 1")
        _positive("calibration.registration", outlier_translation_m=self.outlier_translation_m,
                  outlier_rotation_deg=self.outlier_rotation_deg, max_rms_residual_m=self.max_rms_residual_m)


@dataclass(frozen=True)
class HmdNoiseConfig:
    """Errors added to the HMD pipeline for sim-to-real studies (all zero: the pipeline as measured)."""

    tracking_noise_m: float = 0.0  # std per axis of the head-tracked camera position, per frame
    tracking_noise_deg: float = 0.0  # std per axis of the head-tracked camera rotation vector, per frame
    calibration_error_m: float = 0.0  # fixed offset (norm) added to T_base_hmd, random direction
    calibration_error_deg: float = 0.0  # fixed rotation (angle) added to T_base_hmd about `pivot`, random axis
    pivot: tuple[float, float, float] = (0.475, 0.1, 0.0)  # base point the rotation error turns about (workspace centre)
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("tracking_noise_m", "tracking_noise_deg", "calibration_error_m", "calibration_error_deg"):
            if getattr(self, name) < 0:
                raise ConfigError(f"calibration.hmd.{name} must be >= 0, got {getattr(self, name)}")


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
