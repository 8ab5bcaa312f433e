"""Annotations and their cache: the run's `annotations.jsonl`, written as answers arrive, reloaded on resume.

An annotation marks the waypoint of the current phase (TCP target, gripper state), which depends on the
phase and on where the object or goal is, not on where the arm happens to be. Two observations match
when they are in the same phase and the phase's anchor differs by at most `tolerance` metres per
coordinate: the object position for approach and grasp, its xy for lift (the object rises with the
cup), the goal for transport and release (Sec. V-G: identical inputs are never asked twice).

A re-marked waypoint (the arm never reached the first one) supersedes the earlier record: both stay in
the file, in order, and loading keeps only the newest.
"""

from __future__ import annotations

import json
import logging
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from mrguide.errors import InputError
from mrguide.task import OBS_DIM, OBS_GOAL, OBS_OBJECT, OBS_PROGRESS, Phase, phase_from_progress

log = logging.getLogger(__name__)


class AnnotationError(InputError):
    """An annotation that cannot be used (NaN/inf, wrong shape), or an annotation file that cannot be read."""


@dataclass(frozen=True)
class Annotation:
    """An expert waypoint in the robot base frame: TCP target (m), gripper command (+1 on / -1 off), provenance.

    `source` says who produced it ("oracle", "simulated", "file", "live"); `info` holds what else the
    run log keeps with it (client, request id, latency). `here`: the person said "not there — here", teaching
    where the part is gripped or set down (`MarkFusion.teach`), not marking it under the centre prior.
    """

    target: np.ndarray
    grip: float
    source: str = "oracle"
    info: dict[str, Any] = field(default_factory=dict)
    here: bool = False

    def __post_init__(self) -> None:
        t = np.asarray(self.target, dtype=float)
        if t.shape != (3,) or not np.all(np.isfinite(t)):
            raise AnnotationError(f"annotation target must be 3 finite numbers (m), got {self.target!r}")
        if isinstance(self.grip, bool) or not isinstance(self.grip, (int, float)) or not math.isfinite(self.grip):
            raise AnnotationError(
                f"annotation gripper command must be a finite number (+1 on, -1 off), got {self.grip!r}"
            )


@dataclass(frozen=True)
class CacheHit:
    """A cached annotation and its record number in the cache (and file)."""

    index: int
    annotation: Annotation


def anchor_key(obs: np.ndarray) -> np.ndarray:
    """What an annotation depends on: the phase's anchor position and the phase (scaled apart)."""
    obs = np.asarray(obs, dtype=float)
    phase = phase_from_progress(obs[OBS_PROGRESS])
    anchor = obs[OBS_OBJECT].copy() if phase <= Phase.LIFT else obs[OBS_GOAL].copy()
    if phase == Phase.LIFT:
        anchor[2] = 0.0
    return np.concatenate([anchor, [phase * 1e3]])  # phase scaled so that any difference exceeds any tolerance


class AnnotationCache:
    """Annotations kept and reused for matching observations; appended to a JSONL file as they arrive."""

    def __init__(self, tolerance: float = 0.005, path: str | Path | None = None):
        self.tolerance = tolerance
        self.path = Path(path) if path else None
        self._keys: list[np.ndarray] = []  # a superseded record's key never matches (inf)
        self._observations: list[np.ndarray] = []  # every record's observation, superseded ones included
        self._values: list[Annotation] = []
        self._matrix: np.ndarray | None = None

    def __len__(self) -> int:
        """Annotations in use (superseded ones not counted)."""
        return sum(bool(np.isfinite(k[0])) for k in self._keys)

    def lookup(self, obs: np.ndarray) -> CacheHit | None:
        """The nearest matching annotation within the tolerance, or None."""
        if not self._values:
            return None
        if self._matrix is None or len(self._matrix) != len(self._keys):
            self._matrix = np.array(self._keys)
        diff = np.abs(self._matrix - anchor_key(obs)).max(axis=1)
        i = int(np.argmin(diff))
        return CacheHit(i, self._values[i]) if diff[i] <= self.tolerance else None

    def insert(
        self, obs: np.ndarray, annotation: Annotation, supersedes: int | None = None, persist: bool = True
    ) -> int:
        """Add an annotation (replacing record `supersedes`); it is on disk when this returns. Returns its index."""
        index = len(self._keys)
        if supersedes is not None:
            self._retire(supersedes)
        self._keys.append(anchor_key(obs))
        self._observations.append(np.asarray(obs, dtype=float).copy())
        self._values.append(annotation)
        self._matrix = None
        if persist and self.path is not None:
            record = {
                "id": index,
                "obs": np.asarray(obs, float).tolist(),
                "target": np.asarray(annotation.target, float).tolist(),
                "grip": float(annotation.grip),
                "source": annotation.source,
                **({"here": True} if annotation.here else {}),
                **annotation.info,
                "supersedes": supersedes,
            }
            with self.path.open("a") as fh:
                fh.write(json.dumps(record) + "\n")
                fh.flush()
                os.fsync(fh.fileno())
        return index

    def get(self, index: int) -> Annotation:
        """Record `index` (superseded or not)."""
        return self._values[index]

    def history(self) -> list[tuple[np.ndarray, Annotation]]:
        """Every record in insertion order, superseded ones included: (observation, annotation)."""
        return list(zip(self._observations, self._values))

    def _retire(self, index: int) -> None:
        if not 0 <= index < len(self._keys):
            raise AnnotationError(f"cannot supersede annotation {index}: the cache holds {len(self._keys)}")
        self._keys[index] = np.full_like(self._keys[index], np.inf)  # never matches again

    def load(self, path: str | Path, repair: bool = False) -> int:
        """Read records written by `insert`; returns how many are in use.

        A torn last line (a crash mid-write) is skipped, and with `repair` cut off the file, or a whole last
        record without its newline given one, so the next record starts on a line of its own. Anything else that is not a valid record raises
        AnnotationError naming the file and line.
        """
        path = Path(path)
        try:
            raw = path.read_bytes()
        except OSError as exc:
            raise AnnotationError(f"cannot read annotation file {path}: {exc.strerror or exc}") from exc
        lines = raw.split(b"\n")
        good_end, offset = 0, 0
        for k, line in enumerate(lines):
            offset_next = offset + len(line) + 1
            if line.strip():
                last = k == len(lines) - 1  # no newline after it: possibly torn
                try:
                    obs, ann, supersedes = _parse_record(line, len(self._keys))
                except AnnotationError as exc:
                    if last:
                        log.warning("%s: skipping a torn last line (%s)", path, exc)
                        break
                    raise AnnotationError(f"{path}:{k + 1}: {exc}") from exc
                self.insert(obs, ann, supersedes, persist=False)
            good_end = min(offset_next, len(raw))
            offset = offset_next
        if repair and good_end < len(raw):
            with path.open("r+b") as fh:
                fh.truncate(good_end)
        elif repair and raw and not raw.endswith(b"\n"):  # a whole last record that lost its newline (full disk, crash)
            with path.open("ab") as fh:
                fh.write(b"\n")
                fh.flush()
                os.fsync(fh.fileno())
        return len(self)


def _parse_record(line: bytes, count: int) -> tuple[np.ndarray, Annotation, int | None]:
    try:
        rec = json.loads(line)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise AnnotationError(f"not JSON: {exc}") from exc
    if not isinstance(rec, dict):
        raise AnnotationError(f"a record must be a JSON object, got {type(rec).__name__}")
    for key in ("obs", "target", "grip"):
        if key not in rec:
            raise AnnotationError(f"record has no {key!r}")
    try:
        obs = np.asarray(rec["obs"], dtype=float)
    except (TypeError, ValueError) as exc:
        raise AnnotationError(f"'obs' is not a list of numbers: {exc}") from exc
    if obs.shape != (OBS_DIM,) or not np.all(np.isfinite(obs)):
        raise AnnotationError(f"'obs' must be {OBS_DIM} finite numbers, got shape {obs.shape}")
    try:
        target = np.asarray(rec["target"], dtype=float)
    except (TypeError, ValueError) as exc:
        raise AnnotationError(f"'target' is not a list of numbers: {exc}") from exc
    supersedes = rec.get("supersedes")
    if supersedes is not None and (not isinstance(supersedes, int) or not 0 <= supersedes < count):
        raise AnnotationError(f"'supersedes' must name an earlier record (0..{count - 1}), got {supersedes!r}")
    here = rec.get("here", False)
    if not isinstance(here, bool):
        raise AnnotationError(f"'here' must be true or false, got {here!r}")
    source = rec.get("source", "file")
    info = {k: v for k, v in rec.items() if k not in ("id", "obs", "target", "grip", "source", "supersedes", "here")}
    return obs, Annotation(target, rec["grip"], str(source), info, here), supersedes
