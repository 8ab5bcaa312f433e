"""Expert guidance: the λ schedule (Eq. 11), threshold activation (Eq. 12), bounded projection of
annotations (Eq. 13) and the annotation cache (Sec. V-G: identical inputs are never asked twice)."""

from __future__ import annotations

import json
import logging
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from mrguide.task import TaskConfig, phase_from_progress, phase_target

log = logging.getLogger(__name__)


class AnnotationError(ValueError):
    """An annotation that cannot be used (NaN/inf, wrong shape)."""


def expert_ratio(t: int, horizon: int, lam_max: float = 0.9, lam_min: float = 0.1) -> float:
    """λ_t = max(λ_min, λ_max − t/T (λ_max − λ_min)) (Eq. 11; 0.9 → 0.1 from Table I)."""
    return max(lam_min, lam_max - (t / horizon) * (lam_max - lam_min))


class ThresholdTrigger:
    """Eq. 12: fires once the running sum of an episode's rewards drops below R_th."""

    def __init__(self, r_th: float):
        self.r_th = r_th
        self.total = 0.0

    def reset(self) -> None:
        self.total = 0.0

    def update(self, reward: float) -> bool:
        """Add r_t; True when Σ_{k≤t} r_k < R_th."""
        self.total += float(reward)
        return self.total < self.r_th


def bounded_projection(mr: np.ndarray, reference: np.ndarray, delta: float) -> np.ndarray:
    """Eq. 13: ã = a^e + Δ / max(‖mr − a^e‖, Δ) · (mr − a^e).

    Inside the ball of radius Δ around the reference a^e the annotation is kept as it is; outside it is
    moved onto the sphere. NaN/inf input is refused.
    """
    mr = np.asarray(mr, dtype=float)
    reference = np.asarray(reference, dtype=float)
    if mr.shape != reference.shape or not np.all(np.isfinite(mr)) or not np.all(np.isfinite(reference)):
        raise AnnotationError(f"annotation {mr.tolist()} / reference {reference.tolist()} must be finite and of one shape")
    if not delta > 0:
        raise ValueError(f"Δ must be > 0, got {delta}")
    diff = mr - reference
    return reference + delta / max(float(np.linalg.norm(diff)), delta) * diff


@dataclass(frozen=True)
class Annotation:
    """An expert action in the robot base frame: TCP target (m) and gripper command (+1 / -1)."""

    target: np.ndarray
    grip: float

    def __post_init__(self) -> None:
        t = np.asarray(self.target, dtype=float)
        if t.shape != (3,) or not np.all(np.isfinite(t)) or not np.isfinite(self.grip):
            raise AnnotationError(f"annotation must be a finite 3-vector target and gripper value, got {self.target}, {self.grip}")


class ReferencePose(Protocol):
    """a^e of Eq. 13: the pose an annotation is bounded around."""

    def reference(self, obs: np.ndarray) -> np.ndarray: ...

    def observe(self, obs: np.ndarray, annotation: Annotation) -> None: ...


class NominalReference:
    """In simulation: the task model's nominal phase target (what a perfect annotator would mark)."""

    def __init__(self, task: TaskConfig):
        self.task = task

    def reference(self, obs: np.ndarray) -> np.ndarray:
        return phase_target(phase_from_progress(obs[4]), obs[5:8], obs[8:11], self.task)

    def observe(self, obs: np.ndarray, annotation: Annotation) -> None:
        """Nothing to learn: the model is exact."""


class RunningMedianReference:
    """On the robot: a robust running estimate from recent annotations.

    Per phase, the offset of each annotation from the phase's nominal target is kept for the last
    `window` annotations; the reference is the nominal target plus their coordinate-wise median, so a
    consistent bias of the annotator (or the calibration) is followed while outliers are not.
    """

    def __init__(self, task: TaskConfig, window: int = 25):
        self.task = task
        self.offsets: dict[int, deque] = {k: deque(maxlen=window) for k in range(5)}

    def reference(self, obs: np.ndarray) -> np.ndarray:
        phase = phase_from_progress(obs[4])
        nominal = phase_target(phase, obs[5:8], obs[8:11], self.task)
        offs = self.offsets[phase]
        return nominal + (np.median(np.array(offs), axis=0) if offs else 0.0)

    def observe(self, obs: np.ndarray, annotation: Annotation) -> None:
        phase = phase_from_progress(obs[4])
        self.offsets[phase].append(np.asarray(annotation.target) - phase_target(phase, obs[5:8], obs[8:11], self.task))


class AnnotationCache:
    """Annotations kept and reused for matching observations; appended to a JSONL file as they arrive.

    An annotation marks the waypoint of the current phase, which depends on the phase and on where the
    object or goal is, not on where the arm happens to be. Two observations therefore match when they
    are in the same phase and the phase's anchor differs by at most `tolerance` metres per coordinate:
    the object position for approach and grasp, its xy for lift (the object rises with the cup), the
    goal for transport and release.
    """

    def __init__(self, tolerance: float = 0.005, path: str | Path | None = None):
        self.tolerance = tolerance
        self.path = Path(path) if path else None
        self._keys: list[np.ndarray] = []
        self._values: list[Annotation] = []
        self._matrix: np.ndarray | None = None
        self.asked = 0
        self.reused = 0

    def __len__(self) -> int:
        return len(self._values)

    @staticmethod
    def _key(obs: np.ndarray) -> np.ndarray:
        obs = np.asarray(obs, dtype=float)
        phase = phase_from_progress(obs[4])
        anchor = obs[5:8].copy() if phase <= 2 else obs[8:11].copy()
        if phase == 2:
            anchor[2] = 0.0
        return np.concatenate([anchor, [phase * 1e3]])  # phase scaled so that any difference exceeds any tolerance

    def lookup(self, obs: np.ndarray) -> Annotation | None:
        if not self._values:
            return None
        if self._matrix is None or len(self._matrix) != len(self._keys):
            self._matrix = np.array(self._keys)
        diff = np.abs(self._matrix - self._key(obs)).max(axis=1)
        i = int(np.argmin(diff))
        return self._values[i] if diff[i] <= self.tolerance else None

    def insert(self, obs: np.ndarray, annotation: Annotation, persist: bool = True) -> None:
        self._keys.append(self._key(obs))
        self._values.append(annotation)
        if persist and self.path is not None:
            with self.path.open("a") as fh:
                fh.write(json.dumps({"obs": np.asarray(obs, float).tolist(), "target": np.asarray(annotation.target).tolist(), "grip": float(annotation.grip)}) + "\n")

    def load(self, path: str | Path) -> int:
        """Read annotations written by `insert`; a torn last line (crash mid-write) is skipped. Returns the count."""
        n = 0
        lines = Path(path).read_text().splitlines()
        for k, line in enumerate(lines):
            try:
                rec = json.loads(line)
                self.insert(np.array(rec["obs"]), Annotation(np.array(rec["target"]), float(rec["grip"])), persist=False)
                n += 1
            except (json.JSONDecodeError, KeyError, AnnotationError) as exc:
                if k == len(lines) - 1:
                    log.warning("%s: skipping a torn last line (%s)", path, exc)
                else:
                    raise AnnotationError(f"{path}:{k + 1}: bad annotation record: {exc}") from exc
        return n
