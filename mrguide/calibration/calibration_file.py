"""The calibration file: T_base_hmd with the metadata needed to trust and reuse it (JSON, validated on load)."""

from __future__ import annotations

import json
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mrguide.calibration.camera_model import camera_from_dict
from mrguide.calibration.config import BoardConfig
from mrguide.calibration.detection import canonical_dictionary_name
from mrguide.calibration.errors import CalibrationError, CalibrationFileError
from mrguide.calibration.se3 import is_rigid
from mrguide.config import ConfigError, from_dict
from mrguide.output_files import write_files_atomically

log = logging.getLogger(__name__)

FORMAT = "mrguide-calibration"
VERSION = 1
METHODS = ("board", "markers", "board+markers", "hand-eye")
#: Every key of a calibration file.
KEYS = frozenset(
    {
        "format",
        "version",
        "T_base_hmd",
        "dictionary",
        "marker_size_m",
        "method",
        "rms_residual_m",
        "max_residual_m",
        "n_frames",
        "n_points",
        "created",
        "camera",
        "board",
        "extra",
    }
)
#: Plausibility bounds of the numbers in a calibration file (m, counts).
MAX_MARKER_SIZE_M = 2.0
MAX_RESIDUAL_M = 1.0
MAX_COUNT = 10_000_000


@dataclass(frozen=True)
class CalibrationRecord:
    """A registration of the HMD (or camera) frame to the robot base frame."""

    T_base_hmd: np.ndarray
    dictionary: str
    marker_size_m: float  # single-marker size the detector was configured with
    method: str  # one of METHODS
    rms_residual_m: float
    max_residual_m: float
    n_frames: int
    n_points: int
    created: str = field(default_factory=lambda: time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()))
    camera: dict[str, Any] | None = None  # intrinsics the images were taken with
    board: dict[str, Any] | None = None  # the board config, when a board was used
    extra: dict[str, Any] = field(default_factory=dict)  # method-specific figures (e.g. rejected frames)

    def to_json(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "version": VERSION,
            "T_base_hmd": np.asarray(self.T_base_hmd, dtype=float).tolist(),
            "dictionary": self.dictionary,
            "marker_size_m": self.marker_size_m,
            "method": self.method,
            "rms_residual_m": self.rms_residual_m,
            "max_residual_m": self.max_residual_m,
            "n_frames": self.n_frames,
            "n_points": self.n_points,
            "created": self.created,
            "camera": self.camera,
            "board": self.board,
            "extra": self.extra,
        }

    def encode(self) -> bytes:
        """The calibration file's bytes."""
        return (json.dumps(self.to_json(), indent=2) + "\n").encode()


def save_calibration(record: CalibrationRecord, path: str | Path) -> Path:
    """Write `record` as JSON (atomically: a partial file never replaces a good one)."""
    path = Path(path)
    write_files_atomically({path: record.encode()})
    log.info("wrote calibration %s (rms %.2f mm)", path, record.rms_residual_m * 1e3)
    return path


def load_calibration(
    path: str | Path, expect_dictionary: str | None = None, expect_marker_size_m: float | None = None
) -> CalibrationRecord:
    """Read and validate a calibration file; with `expect_*`, also check it matches the current setup."""
    path = Path(path)
    if not path.is_file():
        raise CalibrationFileError(f"calibration file not found: {path}")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CalibrationFileError(f"{path}: not valid JSON ({exc})") from exc
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise CalibrationFileError(f'{path}: not an mrguide calibration file (missing "format": "{FORMAT}")')
    if data.get("version") != VERSION:
        raise CalibrationFileError(
            f"{path}: calibration format version {data.get('version')!r}, this code reads {VERSION}"
        )
    record = _record_from_json(data, path)
    if expect_dictionary is not None and record.dictionary != canonical_dictionary_name(expect_dictionary):
        raise CalibrationFileError(
            f"{path}: made with dictionary {record.dictionary}, but the current setup uses {expect_dictionary}"
        )
    if expect_marker_size_m is not None and not math.isclose(record.marker_size_m, expect_marker_size_m, rel_tol=1e-6):
        raise CalibrationFileError(
            f"{path}: made with {record.marker_size_m} m markers, but the current setup uses {expect_marker_size_m} m"
        )
    return record


def _record_from_json(data: dict[str, Any], path: Path) -> CalibrationRecord:
    unknown = sorted(set(data) - KEYS)
    if unknown:
        raise CalibrationFileError(f"{path}: unknown keys {unknown}")

    def need(key: str, kind: type | tuple[type, ...]):
        if key not in data:
            raise CalibrationFileError(f"{path}: missing key {key!r}")
        value = data[key]
        if not isinstance(value, kind) or isinstance(value, bool):
            raise CalibrationFileError(f"{path}: {key!r} has the wrong type ({type(value).__name__})")
        return value

    def number(key: str, low: float, high: float, integer: bool = False) -> Any:
        value = need(key, int if integer else (int, float))
        if not (math.isfinite(value) and low <= value <= high):
            raise CalibrationFileError(
                f"{path}: {key!r} = {value!r}: expected {'an integer' if integer else 'a finite number'} "
                f"in [{low:g}, {high:g}]"
            )
        return value

    matrix = need("T_base_hmd", list)
    try:
        T = np.asarray(matrix, dtype=float)
    except (TypeError, ValueError) as exc:
        raise CalibrationFileError(f"{path}: 'T_base_hmd' is not a numeric 4x4 matrix") from exc
    if not is_rigid(T, tol=1e-5):
        raise CalibrationFileError(
            f"{path}: 'T_base_hmd' is not a rigid 4x4 transform (finite, orthonormal, last row 0 0 0 1)"
        )
    name = need("dictionary", str)
    try:
        dictionary = canonical_dictionary_name(name)
    except CalibrationError as exc:
        raise CalibrationFileError(f"{path}: {exc}") from exc
    marker_size = float(number("marker_size_m", 1e-4, MAX_MARKER_SIZE_M))
    rms, worst = (float(number(k, 0.0, MAX_RESIDUAL_M)) for k in ("rms_residual_m", "max_residual_m"))
    if rms > worst * (1 + 1e-9):
        raise CalibrationFileError(f"{path}: rms_residual_m {rms} exceeds max_residual_m {worst}")
    n_frames = int(number("n_frames", 1, MAX_COUNT, integer=True))
    n_points = int(number("n_points", n_frames, MAX_COUNT, integer=True))
    method = need("method", str)
    if method not in METHODS:
        raise CalibrationFileError(f"{path}: unknown method {method!r} (one of {METHODS})")
    camera, board = _camera_and_board(data, path)
    return CalibrationRecord(
        T_base_hmd=T,
        dictionary=dictionary,
        marker_size_m=marker_size,
        method=method,
        rms_residual_m=rms,
        max_residual_m=worst,
        n_frames=n_frames,
        n_points=n_points,
        created=need("created", str),
        camera=camera,
        board=board,
        extra=_optional_table(data, "extra", path) or {},
    )


def _camera_and_board(data: dict[str, Any], path: Path) -> tuple[dict[str, Any] | None, dict[str, Any] | None]:
    """The optional 'camera' (intrinsics) and 'board' tables, each checked as its loader would."""
    camera = _optional_table(data, "camera", path)
    if camera is not None:
        try:
            camera_from_dict(camera, f"{path}: 'camera'")
        except CalibrationError as exc:
            raise CalibrationFileError(str(exc)) from exc
    board = _optional_table(data, "board", path)
    if board is not None:
        try:
            from_dict(BoardConfig, board, where=f"{path}: 'board'")
        except ConfigError as exc:
            raise CalibrationFileError(str(exc)) from exc
    return camera, board


def _optional_table(data: dict[str, Any], key: str, path: Path) -> dict[str, Any] | None:
    value = data.get(key)
    if value is not None and not isinstance(value, dict):
        raise CalibrationFileError(f"{path}: {key!r} must be an object or null, got {type(value).__name__}")
    return value
