"""Expert sources behind one small interface: the scripted oracle, a simulated MR annotator, a file."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Annotated, Protocol

import numpy as np

from mrguide.config import ConfigError, Range, check_number, check_ranges
from mrguide.policies.annotations import Annotation, AnnotationCache, AnnotationError
from mrguide.robot import Workspace
from mrguide.simulated_person import accepts, person_grasp
from mrguide.task import OBS_PROGRESS, PICK_PHASE, TaskConfig, oracle_target, phase_from_progress

#: The simulated annotator of training seed s draws its noise from RNG seed s + this.
ANNOTATOR_SEED_OFFSET = 7919


class ExpertSource(Protocol):
    """Gives an annotation (TCP target in the robot frame + gripper command) for an observation.

    `previous` is the annotation of this waypoint that the arm did not reach (a request to re-mark it).
    None means nobody annotated: the demonstration is dropped. A source that wants to know when an
    annotation it gave is on disk (the live session acknowledges the answer then) has a method
    `recorded(annotation)`, which the trainer calls after the annotation log's fsync. A source through which
    a person can step in at any time has `intervention_requested() -> bool`, which the trainer polls at every
    agent step of the intake window.
    """

    def annotate(self, obs: np.ndarray, previous: Annotation | None = None) -> Annotation | None: ...


class OracleExpert:
    """The task model's scripted expert: exact phase targets and gripper states."""

    def __init__(self, task: TaskConfig):
        self.task = task

    def annotate(self, obs: np.ndarray, previous: Annotation | None = None) -> Annotation:
        target, grip = oracle_target(obs, self.task)
        return Annotation(target, grip, "oracle")


#: Where the simulated person's eyes are (m, robot base frame): standing across the table from the robot,
#: about 0.8 m above the table top (ours; `guidance.noise.viewpoint`).
DEFAULT_VIEWPOINT = (1.3, 0.1, 0.8)


@dataclass(frozen=True)
class AnnotatorNoise:
    """How a simulated MR annotator errs (Sec. V-E), every term zero by default.

    Fig. 7's reading is `sigma` alone (isotropic, fresh per mark). A person in a headset (`configs/runs/person.toml`)
    has a registration bias held for the whole run (`bias_sigma`, drawn once), a per-mark error that is larger
    along the line of sight from `viewpoint` than across it (`sigma_along`, `sigma_across`) and occasional gross
    slips (`outlier_rate`, `outlier_scale`). The terms add: independent Gaussians, each drawn only when non-zero.
    """

    sigma: float = 0.0  # m, std per axis of the marked position (isotropic)
    bias: tuple[float, float, float] = (0.0, 0.0, 0.0)  # m, constant calibration offset
    bias_sigma: float = 0.0  # m, std per axis of a bias drawn once per run (the session's registration error)
    sigma_across: float = 0.0  # m, std per axis across the line of sight
    sigma_along: float = 0.0  # m, std along the line of sight (depth)
    viewpoint: tuple[float, float, float] = DEFAULT_VIEWPOINT  # m, the person's eyes, robot base frame
    outlier_rate: Annotated[float, Range(0.0, 1.0)] = 0.0  # fraction of annotations that are gross mistakes (slips)
    outlier_scale: float = 0.15  # m, std per axis of an outlier's error
    #: m, std per axis (on the part's top) of a correction: the person moves the grip the page shows on the part to
    #: where they judge it belongs, an error of judging a point against what is drawn, not of marking it afresh
    sigma_correction: float = 0.0
    #: A part not gripped at its middle: the person marks where they grip it and teaches it ("not there — here");
    #: false: they mark it, read under the centre prior, as before a person could teach (the comparison)
    teaches: bool = True
    #: Which person of this model marks: 0 the first draw of the bias and of the marks' errors for a training seed,
    #: another number an independent one (a second panel of people)
    draw: Annotated[int, Range(0, 2**32 - 1)] = 0

    def __post_init__(self) -> None:
        for name in ("sigma", "bias_sigma", "sigma_across", "sigma_along", "outlier_scale", "sigma_correction"):
            check_number(f"guidance.noise.{name}", getattr(self, name), 0.0, 1.0, " m")
        check_ranges(self, "guidance.noise")
        for field_name, vec, limit in (("bias", self.bias, 1.0), ("viewpoint", self.viewpoint, 100.0)):
            if len(vec) != 3:
                raise ConfigError(f"guidance.noise.{field_name} = {list(vec)!r}: expected 3 numbers (m)")
            for i, b in enumerate(vec):
                check_number(f"guidance.noise.{field_name}[{i}]", b, -limit, limit, " m")


class SimulatedAnnotator:
    """Oracle + noise: what a person marking targets through an HMD would give.

    The marked point is confined to the workspace box, as the annotation page's gizmo is (a person
    cannot mark outside it), so the simulated annotator and `mrguide annotate bot` answer alike.
    The per-run bias is drawn at construction, from the same RNG as the marks; like the line-of-sight terms it
    draws nothing when zero, so an isotropic annotator's stream is what it always was.
    """

    def __init__(self, task: TaskConfig, noise: AnnotatorNoise, workspace: Workspace, seed: int | None = None):
        grasp = person_grasp(task.part)  # a part not gripped at its middle: the person knows where, and teaches it
        self.teaches = grasp is not None and noise.teaches
        self.oracle = OracleExpert(replace(task, grasp=grasp) if grasp is not None else task)
        self.noise = noise
        self.workspace = workspace
        self.rng = np.random.default_rng(seed if not noise.draw or seed is None else [seed, noise.draw])
        self.run_bias = np.asarray(noise.bias, dtype=float)
        if noise.bias_sigma > 0:
            self.run_bias = self.run_bias + self.rng.normal(0.0, noise.bias_sigma, 3)

    def annotate(self, obs: np.ndarray, previous: Annotation | None = None) -> Annotation:
        exact = self.oracle.annotate(obs)
        marked = self.workspace.clamp(exact.target + self.error(exact.target))[0]
        here = self.teaches and phase_from_progress(obs[OBS_PROGRESS]) == PICK_PHASE
        return Annotation(marked, exact.grip, "simulated", here=here)

    def correct(self, obs: np.ndarray) -> Annotation:
        """The pick answered while the page shows a taught grip on the part (a correction, or the taught point asked
        again): the grip moved to where this person judges it belongs, on the part as drawn (`sigma_correction` per
        axis across its top; no registration bias, no line of sight: the grip and the part are drawn together),
        taught (`here`)."""
        exact = self.oracle.annotate(obs)
        off = np.r_[self.rng.normal(0.0, self.noise.sigma_correction, 2), 0.0] if self.noise.sigma_correction else 0.0
        return Annotation(self.workspace.clamp(exact.target + off)[0], exact.grip, "simulated", here=True)

    def corrects(self, grasp: list[float] | None) -> bool:
        """Whether this person, shown that the cell grips the part at `grasp` (m, part frame; None: the centre
        prior, before anything was taught), steps in to correct it: only a person who teaches, only a taught grip."""
        return self.teaches and grasp is not None and not accepts(self.oracle.task.part, grasp)

    def error(self, point: np.ndarray) -> np.ndarray:
        """One mark's error (m) at `point`: the run's bias plus fresh isotropic, line-of-sight and slip terms."""
        n = self.noise
        err = self.rng.normal(0.0, n.sigma, 3) + self.run_bias
        if n.sigma_along > 0 or n.sigma_across > 0:
            sight = np.asarray(point, dtype=float) - np.asarray(n.viewpoint, dtype=float)
            u = sight / max(float(np.linalg.norm(sight)), 1e-9)
            across = self.rng.normal(0.0, 1.0, 3)
            err = err + n.sigma_along * self.rng.normal() * u + n.sigma_across * (across - (across @ u) * u)
        if n.outlier_rate > 0 and self.rng.random() < n.outlier_rate:
            err = err + self.rng.normal(0.0, n.outlier_scale, 3)
        return err


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
            raise AnnotationError(
                f"{self.path}: no recorded annotation within {self._cache.tolerance} m of this observation"
            )
        ann = hit.annotation
        return Annotation(ann.target, ann.grip, "file", {"replayed_from": ann.source}, ann.here)
