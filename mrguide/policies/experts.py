"""Expert sources behind one small interface: the scripted oracle, a simulated MR annotator, a file."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from mrguide.policies.guidance import Annotation, AnnotationCache, AnnotationError
from mrguide.task import TaskConfig, oracle_target


class ExpertSource(Protocol):
    """Gives an annotation (TCP target in the robot frame + gripper command) for an observation."""

    def annotate(self, obs: np.ndarray) -> Annotation: ...


class OracleExpert:
    """The task model's scripted expert: exact phase targets and gripper states."""

    def __init__(self, task: TaskConfig):
        self.task = task

    def annotate(self, obs: np.ndarray) -> Annotation:
        target, grip = oracle_target(obs, self.task)
        return Annotation(target, grip)


@dataclass(frozen=True)
class AnnotatorNoise:
    """How a simulated MR annotator errs (Sec. V-E): Gaussian noise, a calibration bias, outliers."""

    sigma: float = 0.0  # m, std per axis of the marked position
    bias: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m, constant calibration offset
    outlier_rate: float = 0.0  # fraction of annotations that are gross mistakes
    outlier_scale: float = 0.15  # m, std per axis of an outlier's error

    def __post_init__(self) -> None:
        if self.sigma < 0 or self.outlier_scale < 0 or not 0.0 <= self.outlier_rate <= 1.0:
            raise ValueError(f"annotator noise: sigma/outlier_scale must be >= 0 and outlier_rate in [0, 1], got {self}")


class SimulatedAnnotator:
    """Oracle + noise: what a person marking targets through an HMD would give."""

    def __init__(self, task: TaskConfig, noise: AnnotatorNoise, seed: int | None = None):
        self.oracle = OracleExpert(task)
        self.noise = noise
        self.rng = np.random.default_rng(seed)

    def annotate(self, obs: np.ndarray) -> Annotation:
        exact = self.oracle.annotate(obs)
        n = self.noise
        err = self.rng.normal(0.0, n.sigma, 3) + np.asarray(n.bias)
        if n.outlier_rate > 0 and self.rng.random() < n.outlier_rate:
            err = err + self.rng.normal(0.0, n.outlier_scale, 3)
        return Annotation(exact.target + err, exact.grip)


class FileExpert:
    """Annotations replayed from a JSONL file of {"obs", "target", "grip"} records (e.g. a live MR session)."""

    def __init__(self, path: str | Path, tolerance: float = 0.005):
        self.path = Path(path)
        if not self.path.is_file():
            raise AnnotationError(f"annotation file not found: {self.path}")
        self._cache = AnnotationCache(tolerance)
        try:
            n = self._cache.load(self.path)
        except (json.JSONDecodeError, AnnotationError) as exc:
            raise AnnotationError(f"{self.path}: {exc}") from exc
        if n == 0:
            raise AnnotationError(f"{self.path}: no annotations in the file")

    def annotate(self, obs: np.ndarray) -> Annotation:
        ann = self._cache.lookup(obs)
        if ann is None:
            raise AnnotationError(f"{self.path}: no recorded annotation within {self._cache.tolerance} m of this observation")
        return ann
