"""Expert sources behind one small interface: the scripted oracle, a simulated MR annotator, a file."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np

from mrguide.config import ConfigError, check_number
from mrguide.policies.annotations import Annotation, AnnotationCache, AnnotationError
from mrguide.robot import Workspace
from mrguide.task import TaskConfig, oracle_target

#: The simulated annotator of training seed s draws its noise from RNG seed s + this.
ANNOTATOR_SEED_OFFSET = 7919


class ExpertSource(Protocol):
    """Gives an annotation (TCP target in the robot frame + gripper command) for an observation.

    `previous` is the annotation of this waypoint that the arm did not reach (a request to re-mark it).
    None means nobody annotated: the demonstration is dropped.
    """

    def annotate(self, obs: np.ndarray, previous: Annotation | None = None) -> Annotation | None: ...


class OracleExpert:
    """The task model's scripted expert: exact phase targets and gripper states."""

    def __init__(self, task: TaskConfig):
        self.task = task

    def annotate(self, obs: np.ndarray, previous: Annotation | None = None) -> Annotation:
        target, grip = oracle_target(obs, self.task)
        return Annotation(target, grip, "oracle")


@dataclass(frozen=True)
class AnnotatorNoise:
    """How a simulated MR annotator errs (Sec. V-E): Gaussian noise, a calibration bias, outliers."""

    sigma: float = 0.0  # m, std per axis of the marked position
    bias: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m, constant calibration offset
    outlier_rate: float = 0.0  # fraction of annotations that are gross mistakes
    outlier_scale: float = 0.15  # m, std per axis of an outlier's error

    def __post_init__(self) -> None:
        check_number("guidance.noise.sigma", self.sigma, 0.0, 1.0, " m")
        check_number("guidance.noise.outlier_rate", self.outlier_rate, 0.0, 1.0)
        check_number("guidance.noise.outlier_scale", self.outlier_scale, 0.0, 1.0, " m")
        if len(self.bias) != 3:
            raise ConfigError(f"guidance.noise.bias = {list(self.bias)!r}: expected 3 numbers (m)")
        for i, b in enumerate(self.bias):
            check_number(f"guidance.noise.bias[{i}]", b, -1.0, 1.0, " m")


class SimulatedAnnotator:
    """Oracle + noise: what a person marking targets through an HMD would give.

    The marked point is confined to the workspace box, as the annotation page's gizmo is (a person
    cannot mark outside it), so the simulated annotator and `mrguide annotate bot` answer alike.
    """

    def __init__(self, task: TaskConfig, noise: AnnotatorNoise, workspace: Workspace, seed: int | None = None):
        self.oracle = OracleExpert(task)
        self.noise = noise
        self.workspace = workspace
        self.rng = np.random.default_rng(seed)

    def annotate(self, obs: np.ndarray, previous: Annotation | None = None) -> Annotation:
        exact = self.oracle.annotate(obs)
        n = self.noise
        err = self.rng.normal(0.0, n.sigma, 3) + np.asarray(n.bias)
        if n.outlier_rate > 0 and self.rng.random() < n.outlier_rate:
            err = err + self.rng.normal(0.0, n.outlier_scale, 3)
        return Annotation(self.workspace.clamp(exact.target + err)[0], exact.grip, "simulated")


class FileExpert:
    """Annotations replayed from an `annotations.jsonl` (e.g. of a live MR session); re-marks replay as their newest."""

    def __init__(self, path: str | Path, tolerance: float = 0.005):
        self.path = Path(path)
        if not self.path.is_file():
            raise AnnotationError(f"annotation file not found: {self.path}")
        self._cache = AnnotationCache(tolerance)
        if self._cache.load(self.path) == 0:
            raise AnnotationError(f"{self.path}: no annotations in the file")

    def annotate(self, obs: np.ndarray, previous: Annotation | None = None) -> Annotation:
        hit = self._cache.lookup(obs)
        if hit is None:
            raise AnnotationError(f"{self.path}: no recorded annotation within {self._cache.tolerance} m of this observation")
        ann = hit.annotation
        return Annotation(ann.target, ann.grip, "file", {"replayed_from": ann.source})
