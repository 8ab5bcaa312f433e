"""Expert guidance: the λ schedule (Eq. 11), threshold activation (Eq. 12), bounded projection of
annotations (Eq. 13) and the references it bounds around. The annotation cache is in `annotations`."""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Annotated, Protocol

import numpy as np

from mrguide.config import ConfigError, Range, check_ranges
from mrguide.policies.annotations import Annotation, AnnotationError
from mrguide.policies.choices import (
    EXPERT_SOURCES,
    MARKS_MODES,
    REFERENCES,
    ExpertSourceName,
    MarksMode,
    ReferenceName,
)
from mrguide.policies.experts import AnnotatorNoise
from mrguide.task import N_PHASES, OBS_GOAL, OBS_OBJECT, OBS_PROGRESS, TaskConfig, phase_from_progress, phase_target

log = logging.getLogger(__name__)


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
        raise AnnotationError(
            f"annotation {mr.tolist()} / reference {reference.tolist()} must be finite and of one shape"
        )
    if not delta > 0:
        raise ValueError(f"Δ must be > 0, got {delta}")
    diff = mr - reference
    return reference + delta / max(float(np.linalg.norm(diff)), delta) * diff


class ReferencePose(Protocol):
    """a^e of Eq. 13: the pose an annotation is bounded around."""

    task: TaskConfig  # the task whose phase targets it starts from (a taught grasp replaces it)

    def reference(self, obs: np.ndarray) -> np.ndarray: ...

    def observe(self, obs: np.ndarray, annotation: Annotation) -> None: ...


class NominalReference:
    """In simulation: the task model's nominal phase target (what a perfect annotator would mark)."""

    def __init__(self, task: TaskConfig):
        self.task = task

    def reference(self, obs: np.ndarray) -> np.ndarray:
        return phase_target(phase_from_progress(obs[OBS_PROGRESS]), obs[OBS_OBJECT], obs[OBS_GOAL], self.task)

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
        self.offsets: dict[int, deque] = {k: deque(maxlen=window) for k in range(N_PHASES)}

    def reference(self, obs: np.ndarray) -> np.ndarray:
        phase = phase_from_progress(obs[OBS_PROGRESS])
        nominal = phase_target(phase, obs[OBS_OBJECT], obs[OBS_GOAL], self.task)
        offs = self.offsets[phase]
        return nominal + (np.median(np.array(offs), axis=0) if offs else 0.0)

    def observe(self, obs: np.ndarray, annotation: Annotation) -> None:
        phase = phase_from_progress(obs[OBS_PROGRESS])
        nominal = phase_target(phase, obs[OBS_OBJECT], obs[OBS_GOAL], self.task)
        self.offsets[phase].append(np.asarray(annotation.target) - nominal)


#: The reference of each guidance.reference.
REFERENCE_POSES: dict[ReferenceName, Callable[[TaskConfig], ReferencePose]] = {
    "nominal": NominalReference,
    "running_median": RunningMedianReference,
}


@dataclass(frozen=True)
class PoseError:
    """How the cell perceives the part's position in the expert path ([guidance.pose]; zero: as observed). Where a
    person or a noisy annotator marks, the figures set the HMD pipeline's assumed errors (configs/runs/person.toml):
    a registration bias drawn once per run and a fresh error per look, as the sim-to-real HMD condition has them."""

    #: std per axis of each look's error (HMD tracking noise: 3 mm in the real cell)
    sigma: Annotated[float, Range(0.0, 0.1, " m")] = 0.0
    #: std per axis of the run's registration bias (HMD calibration error: ~5 mm norm)
    bias_sigma: Annotated[float, Range(0.0, 0.1, " m")] = 0.0

    def __post_init__(self) -> None:
        check_ranges(self, "guidance.pose")


#: What a person's run (`source = "live"`) perceives the part through unless [guidance.pose] says otherwise: the HMD
#: pipeline's assumed errors of configs/cells/real_cell.toml (3 mm tracking noise per look; its 5 mm calibration error
#: as about 3 mm per axis), as configs/runs/person.toml sets them.
LIVE_POSE = PoseError(sigma=0.003, bias_sigma=0.003)


@dataclass(frozen=True)
class GuidanceConfig:
    """Expert guidance ([guidance] in a TOML config)."""

    enabled: bool = True
    r_threshold: Annotated[float, Range(-1e4, 0.0)] = -5.0  # R_th of Eq. 12 (ours; the paper gives no value)
    #: expert intake window: the first 10k of 20k steps (paper, Sec. IV-B)
    intake_steps: Annotated[int, Range(0, 10**9)] = 10_000
    lam_max: float = 0.9  # λ_max (Table I)
    lam_min: float = 0.1  # λ_min (Table I)
    delta: Annotated[float, Range(1e-4, 1.0, " m")] = 0.05  # Δ of Eq. 13, m (ours)
    #: a^e of Eq. 13: "running_median" (ours), the task model's target shifted by the median offset of the recent
    #: marks, so no ground truth corrects a mark; or "nominal", the task model's target itself (simulation only).
    reference: ReferenceName = "running_median"
    #: observations this close reuse a cached annotation
    cache_tolerance: Annotated[float, Range(0.0, 0.1, " m")] = 0.005
    #: expert steps on one waypoint without reaching it before it is asked again (0: never; ours)
    reask_after: Annotated[int, Range(0, 10**6)] = 15
    #: What a person marks per demonstration. "pick_place" (ours): the grasp point and the set-down point, each
    #: fused with every earlier one as a measurement of one offset from the part (pick) or the goal (place), the
    #: five waypoints following from the fused marks (task.waypoint_from_mark). "phases" (the paper's): every
    #: phase's waypoint, used as marked. Both bounded by Eq. 13 around `reference`.
    marks: MarksMode = "pick_place"
    #: "oracle", "annotator" (oracle + noise), "file", "live" (`--expert live`), or a registered source
    source: ExpertSourceName | str = "annotator"
    noise: AnnotatorNoise = field(default_factory=AnnotatorNoise)
    #: None: the source's own (`pose_error`): a person's (`live`) sees the part as the cell does, `LIVE_POSE`; the
    #: simulated sources as observed
    pose: PoseError | None = None
    #: m: a kind of mark (pick or place) is not asked again once the median of its marks is known to within this per
    #: axis (its standard error, from the marks' own spread; at least 3 marks), nor the pick once a grasp sealed
    #: (ours: a person's time goes where an answer carries information; mark_fusion.py).
    mark_precision: Annotated[float, Range(0.0, 1.0, " m")] = 0.005
    #: m, std per axis of fresh Gaussian noise on every stored expert action, after Eq. 13 (so the bound cannot
    #: filter it), while the arm follows the clean one: Fig. 7's "stored" reading (label noise). Not clipped to
    #: the action box: near its floor — the grasp target lies 2 mm above it — clipping would bias the grasp
    #: height's labels upwards. `noise` above is the "marks" reading: each mark off by an error of its own.
    action_noise: Annotated[float, Range(0.0, 1.0, " m")] = 0.0
    annotation_file: str = ""  # for source = "file"

    def __post_init__(self) -> None:
        if self.reference not in REFERENCES:
            raise ConfigError(f"guidance.reference must be {_either(REFERENCES)}, got {self.reference!r}")
        if self.marks not in MARKS_MODES:
            raise ConfigError(f"guidance.marks must be {_either(MARKS_MODES)}, got {self.marks!r}")
        if self.source not in EXPERT_SOURCES:
            raise ConfigError(f"guidance.source must be {_either(EXPERT_SOURCES)}, got {self.source!r}")
        if self.source == "file" and not self.annotation_file:
            raise ConfigError("guidance.source = 'file' needs guidance.annotation_file")
        if not 0.0 <= self.lam_min <= self.lam_max <= 1.0:
            raise ConfigError(f"guidance: need 0 <= lam_min <= lam_max <= 1, got {self.lam_min}, {self.lam_max}")
        check_ranges(self, "guidance")

    @property
    def pose_error(self) -> PoseError:
        """How the expert path perceives the part: [guidance.pose] if set, else the source's own (`pose`)."""
        if self.pose is not None:
            return self.pose
        return LIVE_POSE if self.source == "live" else PoseError()


def _either(choices: Sequence[str]) -> str:
    """'a' or 'b'; 'a', 'b' or 'c'."""
    quoted = [repr(c) for c in choices]
    return f"{', '.join(quoted[:-1])} or {quoted[-1]}"
