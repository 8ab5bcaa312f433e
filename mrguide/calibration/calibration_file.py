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

from mrguide.calibration.detection import canonical_dictionary_name
from mrguide.calibration.errors import CalibrationError, CalibrationFileError
from mrguide.calibration.se3 import is_rigid

log = logging.getLogger(__name__)

FORMAT = "mrguide-calibration"
VERSION = 1
METHODS = ("board", "markers", "board+markers", "hand-eye")


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


def save_calibration(record: CalibrationRecord, path: str | Path) -> Path:
    """Write `record` as JSON (atomically: a partial file never replaces a good one)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(record.to_json(), indent=2) + "\n")
    tmp.replace(path)
    log.info("wrote calibration %s (rms %.2f mm)", path, record.rms_residual_m * 1e3)
    return path


def load_calibration(path: str | Path, expect_dictionary: str | None = None,
                     expect_marker_size_m: float | None = None) -> CalibrationRecord:
    """Read and validate a calibration file; with `expect_*`, also check it matches the current setup."""
    path = Path(path)
    if not path.is_file():
        raise CalibrationFileError(f"calibration file not found: {path}")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise CalibrationFileError(f"{path}: not valid JSON ({exc})") from exc
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise CalibrationFileError(f"{path}: not an mrguide calibration file (missing \"format\": \"{FORMAT}\")")
    if data.get("version") != VERSION:
        raise CalibrationFileError(f"{path}: calibration format version {data.get('version')!r}, this code reads {VERSION}")
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
    def need(key: str, kind: type | tuple[type, ...]):
        if key not in data:
            raise CalibrationFileError(f"{path}: missing key {key!r}")
        value = data[key]
        if not isinstance(value, kind) or isinstance(value, bool):
            raise CalibrationFileError(f"{path}: {key!r} has the wrong type ({type(value).__name__})")
        return value

    matrix = need("T_base_hmd", list)
    try:
        T = np.asarray(matrix, dtype=float)
    except (TypeError, ValueError) as exc:
        raise CalibrationFileError(f"{path}: 'T_base_hmd' is not a numeric 4x4 matrix") from exc
    if not is_rigid(T, tol=1e-5):
        raise CalibrationFileError(f"{path}: 'T_base_hmd' is not a rigid 4x4 transform")
    name = need("dictionary", str)
    try:
        dictionary = canonical_dictionary_name(name)
    except CalibrationError as exc:
        raise CalibrationFileError(f"{path}: {exc}") from exc
    numbers = {k: float(need(k, (int, float))) for k in ("marker_size_m", "rms_residual_m", "max_residual_m")}
    if not all(math.isfinite(v) and v >= 0 for v in numbers.values()) or numbers["marker_size_m"] == 0:
        raise CalibrationFileError(f"{path}: marker size and residuals must be finite and non-negative: {numbers}")
    method = need("method", str)
    if method not in METHODS:
        raise CalibrationFileError(f"{path}: unknown method {method!r} (one of {METHODS})")
    return CalibrationRecord(
        T_base_hmd=T,
        dictionary=dictionary,
        marker_size_m=numbers["marker_size_m"],
        method=method,
        rms_residual_m=numbers["rms_residual_m"],
        max_residual_m=numbers["max_residual_m"],
        n_frames=int(need("n_frames", int)),
        n_points=int(need("n_points", int)),
        created=need("created", str),
        camera=data.get("camera"),
        board=data.get("board"),
        extra=data.get("extra") or {},
    )
