"""A deploy session: a sequence of episodes on a connected cobot, and its summary."""

from __future__ import annotations

import logging
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Annotated

import numpy as np

from mrguide.config import ConfigError, Range, check_number, check_ranges
from mrguide.deploy.camera import CameraSourceConfig
from mrguide.deploy.cell_learning import LearningConfig
from mrguide.deploy.cycles import CycleConfig
from mrguide.deploy.episode import EpisodeReport, RunStopped
from mrguide.deploy.runtime import Runtime
from mrguide.deploy.runtime_config import RuntimeConfig
from mrguide.drivers.errors import DriverError
from mrguide.pose_source import ObjectPoseSource, PoseUnavailable
from mrguide.task import Outcome

log = logging.getLogger(__name__)

#: Most episodes of one session.
MAX_EPISODES = 100_000
#: Farthest a goal or object may be from the robot base on any axis (m): beyond the reach of any cobot.
MAX_REACH_M = 5.0
POSE_SOURCES = ("fixed", "camera", "hmd")


@dataclass(frozen=True)
class DeployConfig:
    """A deploy session ([deploy] in a TOML config)."""

    bus_config: str = ""  # CAN bus description (TOML), relative to the config file; "" = defaults (virtual bus)
    episodes: Annotated[int, Range(1, MAX_EPISODES)] = 5
    seed: Annotated[int, Range(0, 2**32 - 1)] = 0  # dry run: object and goal layouts
    log_dir: str = "runs/deploy"
    #: Real robot with the exact-pose model: where the object is placed for each episode (base frame, m).
    object_position: tuple[float, float, float] = (0.50, -0.075, 0.025)
    #: Goals (object centre, m), used in turn.
    goals: tuple[tuple[float, float, float], ...] = ((0.50, 0.21, 0.025),)
    #: Where the object pose comes from: "fixed" (`object_position`), "camera" (`[deploy.camera]`; in a dry
    #: run the camera's frames are rendered by the twin) or, in a dry run only, "hmd" (the simulated headset of the
    #: cell's `[calibration.hmd]`, as sim2real's HMD conditions: no headset streams poses to a real cell yet).
    pose_source: str = "fixed"
    camera: CameraSourceConfig = field(default_factory=CameraSourceConfig)
    #: Home tolerance, carried-object tracking, missing poses ([deploy.runtime]).
    runtime: RuntimeConfig = field(default_factory=RuntimeConfig)
    #: Production cycles (`deploy --cycles`): retries, alarms, the pick region ([deploy.cycles]).
    cycles: CycleConfig = field(default_factory=CycleConfig)
    #: Learning on the cell (`deploy --cycles N --learn RUN_DIR`): its exploration ([deploy.learning]).
    learning: LearningConfig = field(default_factory=LearningConfig)

    def __post_init__(self) -> None:
        if self.pose_source not in POSE_SOURCES:
            raise ConfigError(f"deploy.pose_source = {self.pose_source!r}: expected one of {', '.join(POSE_SOURCES)}")
        if self.pose_source == "camera" and not self.camera.calibration:
            raise ConfigError('deploy.camera.calibration: pose_source = "camera" needs the camera\'s calibration file')
        check_ranges(self, "deploy")
        if not self.log_dir:
            raise ConfigError("deploy.log_dir must not be empty")
        if not self.goals:
            raise ConfigError("deploy.goals: at least one goal is needed")
        for i, goal in enumerate(self.goals):
            for k, v in enumerate(goal):
                check_number(f"deploy.goals[{i}][{k}]", v, -MAX_REACH_M, MAX_REACH_M, " m")
        for k, v in enumerate(self.object_position):
            check_number(f"deploy.object_position[{k}]", v, -MAX_REACH_M, MAX_REACH_M, " m")


@dataclass
class DeploySummary:
    """Outcomes, safety events and timing of a session."""

    episodes: list[EpisodeReport] = field(default_factory=list)
    stopped: str | None = None  # why the run ended early, if it did
    recoveries: int = 0  # safety stops after which the run went on (fault reset, next episode)
    cycle_lateness_p99_ms: float = 0.0
    cycle_work_p99_ms: float = 0.0
    cycle_work_max_ms: float = 0.0
    missed_cycles: int = 0

    @property
    def successes(self) -> int:
        return sum(e.outcome == Outcome.SUCCESS.value for e in self.episodes)

    def outcomes(self) -> Counter:
        return Counter(e.outcome.value for e in self.episodes)

    def events(self) -> Counter:
        c: Counter = Counter()
        for e in self.episodes:
            c.update(e.events)
        return c

    def latency_ms(self) -> np.ndarray:
        return np.array([x for e in self.episodes for x in e.latency_ms])

    def inference_ms(self) -> np.ndarray:
        return np.array([x for e in self.episodes for x in e.inference_ms])

    def text(self) -> str:
        n = len(self.episodes)
        lines = [
            f"episodes: {n}, successes: {self.successes} ({self.successes / max(n, 1):.0%})",
            f"outcomes: {dict(self.outcomes())}",
            f"safety events: {dict(self.events()) or 'none'}",
        ]
        lat, inf = self.latency_ms(), self.inference_ms()
        if len(lat):
            lines.append(
                f"decision latency p50/p99: {np.percentile(lat, 50):.2f} / {np.percentile(lat, 99):.2f} ms; "
                f"policy inference median {np.median(inf):.3f} ms"
            )
        lines.append(
            f"control cycle lateness p99: {self.cycle_lateness_p99_ms:.2f} ms, work p99/max: "
            f"{self.cycle_work_p99_ms:.2f} / {self.cycle_work_max_ms:.2f} ms, missed cycles: {self.missed_cycles}"
        )
        if self.recoveries:
            lines.append(f"safety stops recovered from (fault reset, next episode): {self.recoveries}")
        if self.stopped:
            lines.append(f"run stopped early: {self.stopped}")
        return "\n".join(lines)


def run_session(
    runtime: Runtime,
    goals: Sequence[np.ndarray],
    before_episode: Callable[[int], None] | None = None,
    after_episode: Callable[[EpisodeReport], None] | None = None,
    max_recoveries: int = 0,
) -> DeploySummary:
    """Home, (set the scene,) run one episode per goal.

    A safety stop (RunStopped, or a driver fault latched between episodes) fails its episode as
    "safety_stop" and ends the session with a reason, unless `max_recoveries` allows a fault reset and
    the next episode (evaluations in the simulated cell; the real robot wants its operator). A pose
    source that has no pose while the scene is set (`before_episode`) is such a stop too."""
    summary = DeploySummary()

    def record(report: EpisodeReport) -> None:
        summary.episodes.append(report)
        if after_episode:
            after_episode(report)

    try:
        for i, goal in enumerate(goals):
            try:
                runtime.home()
                if before_episode:
                    _set_scene(before_episode, i)
                report = runtime.run_episode(goal, i)
            except (RunStopped, DriverError) as exc:
                stopped = exc.report if isinstance(exc, RunStopped) else None
                record(stopped or EpisodeReport(i, Outcome.SAFETY_STOP, 0, {}))
                if summary.recoveries >= max_recoveries or i == len(goals) - 1:
                    raise
                _recover(runtime, exc)
                summary.recoveries += 1
                continue
            record(report)
    except (RunStopped, DriverError) as exc:
        summary.stopped = str(exc)
        if runtime.log:
            runtime.log.write("run_stopped", reason=str(exc))
        log.error("run stopped: %s", exc)
    finally:
        stats = runtime.cobot.stats()
        summary.cycle_lateness_p99_ms = stats.lateness_p99 * 1e3
        summary.cycle_work_p99_ms, summary.cycle_work_max_ms = stats.work_p99 * 1e3, stats.work_max * 1e3
        summary.missed_cycles = stats.missed_cycles
    return summary


def _set_scene(before_episode: Callable[[int], None], index: int) -> None:
    try:
        before_episode(index)
    except PoseUnavailable as exc:
        raise RunStopped(f"episode {index}: no object pose after setting the scene: {exc}") from exc


def _recover(runtime: Runtime, stop: Exception) -> None:
    log.warning("safety stop: %s; fault reset, going on with the next episode", stop)
    try:
        runtime.recover()
    except DriverError as exc:
        raise RunStopped(f"{stop}; recovery failed: {exc}") from exc


class FixedObjectPose(ObjectPoseSource):
    """The object where the environment model says it is (a fixture or a known placement)."""

    def __init__(self, position: Sequence[float]):
        self.position = np.asarray(position, dtype=float)

    def object_position(self) -> np.ndarray:
        return self.position.copy()
