"""Production cycles: one part after another, a lost part picked again where it lies, alarms when it cannot.

A cycle places one part: the feeder brings it (a dry run's feeder puts a new part at a random pose in the
pick region; on the robot the pose source finds it, or the operator places it) and the policy runs one attempt
toward the cycle's goal from home (where every episode of the training starts). After a place the arm first rises
`depart_height` straight up, clear of the part it let go, as a cell program departs. With `home_between_cycles =
false` the next cycle starts from there instead (a policy trained from such starts; the pose source must see the
part from there, else the arm homes); the first attempt of a run and every attempt after a failed one start from
home. An attempt that fails with the part still on the table (dropped in the lift or transport, no seal, time
out) is a retry: the part is perceived again where it lies and, if it lies in the pick region, picked again; one
that the pose source sees resting at the cycle's goal (within the task's place tolerance) was placed by the
attempt that failed (its horizon ran out as the cup set it down): the cycle is placed, and logged `placed_on_check`.
A part outside the pick region, a pose source that cannot see where a lost part went, or more than
`max_retries` retries raise an alarm: the run stops (`on_alarm = "stop"`) or the part is left for the
operator and the next one fed (`"skip"`). Every retry and alarm, with its cause, goes to the run log.
A safety stop (quick stop) ends the run, as it does in episodes.
"""

from __future__ import annotations

import logging
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Annotated, Protocol

import numpy as np

from mrguide.config import ConfigError, Range, check_number, check_ranges
from mrguide.deploy.episode import RunStopped
from mrguide.deploy.host_stats import FullCollections, HostCounters, miss_anatomy_text, peak_rss_mb, resident_mb
from mrguide.deploy.interrupt import CycleInterrupt
from mrguide.deploy.runtime import Runtime
from mrguide.drivers.errors import DriverError
from mrguide.pose_source import PoseUnavailable
from mrguide.task import Outcome, placed_at_goal

log = logging.getLogger(__name__)

ALARM_ACTIONS = ("stop", "skip")
#: How often a cycle asks the pose source again while it waits for the part to be seen (s).
POSE_POLL_S = 0.1
#: Most cycles of one run.
MAX_CYCLES = 1_000_000
#: Outcomes after which the part lies somewhere on the table and may be picked again.
RETRYABLE = frozenset(
    {Outcome.DROPPED, Outcome.NO_GRASP, Outcome.TIMEOUT, Outcome.MISPLACED, Outcome.ABORTED, Outcome.POSE_LOST}
)


@dataclass(frozen=True)
class CycleConfig:
    """Production cycles ([deploy.cycles] in a TOML config)."""

    #: Failed attempts at one part that are retried; one more raises an alarm. In [0, 100].
    max_retries: Annotated[int, Range(0, 100)] = 3
    #: What an alarm does: "stop" ends the run (the operator clears the cell and resumes), "skip" leaves the
    #: part for the operator and goes on with the next one.
    on_alarm: str = "stop"
    #: Where a part may be picked (xy in the base frame, m: low corner, high corner): the region the policy
    #: was trained on (the twin's object region) plus 2 cm around it.
    pick_region: tuple[tuple[float, float], tuple[float, float]] = ((0.38, -0.17), (0.62, 0.02))
    #: How far (m) a part's centre may be from its resting height on the table and still be picked.
    rest_height_tolerance: Annotated[float, Range(0.0, 0.1, " m")] = 0.01
    #: How long (s) the arm waits at home for the pose source to see the part (a camera or HMD that lost its
    #: view, a tracking restart) before the alarm. In [0, 600].
    pose_wait_s: Annotated[float, Range(0.0, 600.0, " s")] = 10.0
    #: How far (m) the arm rises straight up after a place, clear of the part it let go; 0: no depart move.
    #: In [0, 0.3].
    depart_height: Annotated[float, Range(0.0, 0.3, " m")] = 0.05
    #: Whether each cycle's attempt starts from home (true), or from where the arm departed after the last place
    #: (false: no homing between cycles, for a policy trained to start from there; the shipped policies,
    #: trained from home only, miss grasps from there: docs/results).
    home_between_cycles: bool = True

    def __post_init__(self) -> None:
        check_ranges(self, "deploy.cycles")
        if self.on_alarm not in ALARM_ACTIONS:
            raise ConfigError(f"deploy.cycles.on_alarm = {self.on_alarm!r}: expected one of {', '.join(ALARM_ACTIONS)}")
        low, high = self.pick_region
        for k in range(2):
            check_number(f"deploy.cycles.pick_region[0][{k}]", low[k], -5.0, 5.0, " m")
            check_number(f"deploy.cycles.pick_region[1][{k}]", high[k], low[k], 5.0, " m")
        if not isinstance(self.home_between_cycles, bool):
            raise ConfigError(
                f"deploy.cycles.home_between_cycles = {self.home_between_cycles!r}: expected true or false"
            )


class PartFeeder(Protocol):
    """Brings parts into the pick region: a dry run's simulated feeder, or the operator/camera on the robot."""

    #: Whether the pose source sees a part where it fell (a camera, the twin's exact pose), or only where the
    #: feeder put it (a fixed fixture pose): then a lost part raises an alarm instead of a retry.
    tracks_part: bool

    def next_part(self, cycle: int) -> None:
        """Bring the part of `cycle` into the pick region (or wait until the pose source sees one there)."""
        ...

    def clear_part(self, cycle: int) -> None:
        """Remove the part an alarm left behind (`on_alarm = "skip"`)."""
        ...


@dataclass(frozen=True)
class CycleRun:
    """Which cycles to run and how: `count` cycles from `start` (a resumed run goes on from its log's count)."""

    start: int
    count: int
    seed: int  # a dry run's feeder: part poses and goals
    config: CycleConfig
    after_cycle: Callable[[CycleReport], None] | None = None
    interrupt: CycleInterrupt | None = None
    first_attempt: int = 0  # the run log's episode index of the first attempt (a resumed run goes on counting)


@dataclass
class CycleReport:
    """One cycle: placed or not, its attempts' outcomes, its time from feeding to the end of the last attempt."""

    cycle: int
    placed: bool
    outcomes: list[str] = field(default_factory=list)
    #: Causes of the failed attempts that were followed by another attempt at this part.
    retries: list[str] = field(default_factory=list)
    alarm: str | None = None
    cycle_s: float = 0.0


@dataclass
class CycleSummary:
    """What a run of cycles did: parts placed, retries by cause, alarms, cycle times and the driver's health."""

    start: int = 0
    cycles: list[CycleReport] = field(default_factory=list)
    stopped: str | None = None
    wall_s: float = 0.0
    missed_cycles: int = 0
    underruns: int = 0
    rss_growth_mb: float = 0.0
    #: Where the control thread's time went in the gaps that skipped deadlines (`MissAnatomy.since`).
    misses: dict = field(default_factory=dict)

    @property
    def placed(self) -> int:
        return sum(c.placed for c in self.cycles)

    def retries(self) -> Counter:
        """Failed attempts followed by another attempt at the same part, by the failed attempt's outcome."""
        return Counter(cause for r in self.cycles for cause in r.retries)

    def cycle_times(self) -> np.ndarray:
        return np.array([c.cycle_s for c in self.cycles if c.placed])

    def parts_per_hour(self) -> float:
        return 3600.0 * self.placed / self.wall_s if self.wall_s > 0 else 0.0

    def as_dict(self) -> dict:
        t = self.cycle_times()
        return {
            "cycles": len(self.cycles),
            "placed": self.placed,
            "alarms": [{"cycle": c.cycle, "reason": c.alarm} for c in self.cycles if c.alarm],
            "retries": dict(self.retries()),
            "cycle_s_median": float(np.median(t)) if len(t) else None,
            "cycle_s_p95": float(np.percentile(t, 95)) if len(t) else None,
            "parts_per_hour": self.parts_per_hour(),
            "wall_s": self.wall_s,
            "missed_cycles": self.missed_cycles,
            "underruns": self.underruns,
            "rss_growth_mb": self.rss_growth_mb,
            **self.misses,
            "stopped": self.stopped,
        }

    def text(self) -> str:
        n, d = len(self.cycles), self.as_dict()
        lines = [
            f"cycles {self.start}..{self.start + n - 1}: {self.placed} of {n} parts placed ({self.placed / max(n, 1):.1%})",
            f"retries: {d['retries'] or 'none'}; alarms: {len(d['alarms'])}",
        ]
        if d["cycle_s_median"] is not None:
            lines.append(
                f"cycle time median {d['cycle_s_median']:.2f} s, p95 {d['cycle_s_p95']:.2f} s; "
                f"{d['parts_per_hour']:.0f} parts per hour"
            )
        lines.append(
            f"missed control cycles: {self.missed_cycles}, setpoint queue ran dry while moving: {self.underruns}, "
            f"peak RSS growth {self.rss_growth_mb:.1f} MB"
        )
        if self.misses.get("miss_gaps"):
            lines.append(miss_anatomy_text(self.misses))
        lines += [f"alarm in cycle {a['cycle']}: {a['reason']}" for a in d["alarms"]]
        if self.stopped:
            lines.append(f"run stopped: {self.stopped}")
        return "\n".join(lines)


def _source_accuracy(source: object) -> float:
    """The pose source's stated accuracy (m, `PoseAccuracy`), 0 for a source that states none."""
    accuracy = getattr(source, "accuracy_m", None)
    return float(accuracy()) if callable(accuracy) else 0.0


class CycleRunner:
    """Runs cycles `start`, `start + 1`, ... on a runtime whose cobot is connected and enabled."""

    def __init__(
        self,
        runtime: Runtime,
        feeder: PartFeeder,
        goal_for: Callable[[int], np.ndarray],
        config: CycleConfig,
        after_cycle: Callable[[CycleReport], None] | None = None,
    ):
        self.rt, self.feeder, self.goal_for, self.cfg = runtime, feeder, goal_for, config
        self.after_cycle = after_cycle
        self.rest_z = 0.5 * runtime.task.object_height
        #: m a part's centre may be off its resting height: the config's, or more where the pose source's own
        #: accuracy is coarser (an HMD's depth: its registration residual)
        self.rest_tolerance = max(config.rest_height_tolerance, _source_accuracy(runtime.pose))
        if self.rest_tolerance > config.rest_height_tolerance:
            log.info("the part's resting height is checked to ±%.3f m: the pose source's accuracy", self.rest_tolerance)
        self._attempt = 0  # episode index in the run log of the next attempt
        self._departed = False  # whether the arm rose from a place and the next attempt may start there
        self._collections = FullCollections()

    def run(
        self, start: int, count: int, interrupt: CycleInterrupt | None = None, first_attempt: int = 0
    ) -> CycleSummary:
        """Cycles `start` .. `start + count - 1`, until an alarm with `on_alarm = "stop"`, a safety stop, or
        `interrupt` (the current cycle is finished first); the attempts numbered from `first_attempt` on."""
        summary = CycleSummary(start=start)
        self._attempt = first_attempt
        rss0, t0 = peak_rss_mb(), time.perf_counter()
        stats0 = self.rt.cobot.stats()
        self._collections.start()
        try:
            for cycle in range(start, start + count):
                if interrupt is not None and interrupt.requested:
                    summary.stopped = "interrupted: the cycle in progress was finished"
                    break
                report = self._cycle(cycle)
                summary.cycles.append(report)
                if self.after_cycle:
                    self.after_cycle(report)
                if report.alarm and self.cfg.on_alarm == "stop":
                    summary.stopped = f"alarm in cycle {cycle}: {report.alarm}"
                    break
        except (RunStopped, DriverError, KeyboardInterrupt) as exc:
            summary.stopped = str(exc) or "interrupted (Ctrl-C twice): quick stop"
            log.error("run stopped: %s", summary.stopped)
        finally:
            self._collections.stop()
            stats = self.rt.cobot.stats()
            summary.wall_s = time.perf_counter() - t0
            summary.missed_cycles = stats.missed_cycles - stats0.missed_cycles
            summary.underruns = stats.underruns - stats0.underruns
            summary.rss_growth_mb = peak_rss_mb() - rss0
            summary.misses = stats.misses.since(stats0.misses)
            self.rt.log.write("cycles_end", **summary.as_dict())
            self.rt.log.sync()
        return summary

    def _cycle(self, cycle: int) -> CycleReport:
        """Feed a part, then attempts until it is placed, an alarm, or a safety stop (RunStopped propagates)."""
        goal = np.asarray(self.goal_for(cycle), dtype=float)
        t0, stats0, host0 = time.perf_counter(), self.rt.cobot.stats(), HostCounters.now()
        gc0 = (self._collections.count, self._collections.seconds)
        report = CycleReport(cycle, placed=False)
        self.rt.log.write("cycle_start", cycle=cycle, goal=goal)
        try:
            try:
                self.feeder.next_part(cycle)
            except PoseUnavailable as exc:
                self._alarm(cycle, report, f"no part came: {exc}")
                return report
            self._attempts(cycle, goal, report)
        finally:
            report.cycle_s = time.perf_counter() - t0
            stats = self.rt.cobot.stats()
            self.rt.log.write(
                "cycle_end",
                cycle=cycle,
                placed=report.placed,
                outcomes=report.outcomes,
                retries=report.retries,
                alarm=report.alarm,
                cycle_s=report.cycle_s,
                rss_mb=resident_mb(),
                missed_cycles=stats.missed_cycles - stats0.missed_cycles,
                underruns=stats.underruns - stats0.underruns,
                work_overruns=stats.work_overruns - stats0.work_overruns,
                **stats.misses.since(stats0.misses),
                **HostCounters.now().since(host0),
                full_gc=self._collections.count - gc0[0],
                full_gc_s=self._collections.seconds - gc0[1],
            )
            self.rt.log.sync()
        return report

    def _attempts(self, cycle: int, goal: np.ndarray, report: CycleReport) -> None:
        """Attempts on the fed part until it is placed (by an attempt, or seen at its goal after one that failed)
        or an alarm ends the cycle."""
        while True:
            part = self._start_attempt()
            if report.outcomes and not isinstance(part, str) and self._rests_at(part, goal):
                report.placed = True
                self.rt.log.write("placed_on_check", cycle=cycle, part=part, goal=goal)
                log.info("cycle %d: the part rests at its goal after attempt %d", cycle, len(report.outcomes))
                return
            problem = part if isinstance(part, str) else self._unpickable(part)
            if not problem and report.outcomes:
                problem = self._retry(cycle, report)
            if problem:
                self._alarm(cycle, report, problem)
                return
            episode = self.rt.run_episode(goal, self._attempt)
            self._attempt += 1
            report.outcomes.append(episode.outcome.value)
            if episode.outcome is Outcome.SUCCESS:
                report.placed = True
                departed = self.cfg.depart_height > 0 and self.rt.depart(self.cfg.depart_height)
                self._departed = departed and not self.cfg.home_between_cycles
                return
            if gone := self._gone(report, episode.outcome):
                self._alarm(cycle, report, gone)
                return

    def _gone(self, report: CycleReport, cause: Outcome) -> str | None:
        """After a failed attempt: why the part cannot be looked for again (the alarm), or None."""
        if cause not in RETRYABLE:
            return f"attempt {len(report.outcomes)} ended {cause.value}: the part is gone"
        if not self.feeder.tracks_part and cause is not Outcome.NO_GRASP:
            return f"attempt ended {cause.value} and the pose source cannot see where the part lies"
        return None

    def _retry(self, cycle: int, report: CycleReport) -> str | None:
        """Before picking the part again: the retry counted and logged, or the alarm of too many attempts."""
        cause = report.outcomes[-1]
        if len(report.outcomes) > self.cfg.max_retries:
            return f"{len(report.outcomes)} failed attempts (last: {cause})"
        report.retries.append(cause)
        self.rt.log.write("retry", cycle=cycle, attempt=len(report.outcomes), cause=cause)
        log.info("cycle %d: attempt %d ended %s; picking the part again", cycle, len(report.outcomes), cause)
        return None

    def _start_attempt(self) -> np.ndarray | str:
        """Bring the arm where the attempt starts and find the part: where the arm departed after the last place
        if the pose source sees the part from there, else home. The part's position, or why no pose came."""
        if self._departed:
            self._departed = False
            try:
                return self._part_position(0.0)
            except PoseUnavailable as exc:
                log.info("the part is not seen from where the arm departed (%s): homing", exc)
        self.rt.home()  # where every policy episode of the training starts, and the camera sees the part
        try:
            return self._part_position(self.cfg.pose_wait_s)
        except PoseUnavailable as exc:
            return f"no pose of the part for {self.cfg.pose_wait_s:g} s: {exc}"

    def _rests_at(self, part: np.ndarray, goal: np.ndarray) -> bool:
        """Whether the part, as the pose source sees it, rests on the table at `goal` (the task's place rule)."""
        return self._on_table(part) and placed_at_goal(self.rt.task, part, goal)

    def _on_table(self, part: np.ndarray) -> bool:
        """Whether the part's centre, as seen, is at its resting height on the table (within `rest_tolerance`)."""
        return abs(float(part[2]) - self.rest_z) <= self.rest_tolerance

    def _part_position(self, wait_s: float) -> np.ndarray:
        """The part's position from the pose source, asked again for `wait_s` s (PoseUnavailable after that)."""
        deadline = time.monotonic() + wait_s
        while True:
            try:
                return self.rt.pose.object_position()
            except PoseUnavailable:
                if time.monotonic() >= deadline:
                    raise
                time.sleep(POSE_POLL_S)

    def _unpickable(self, obj: np.ndarray) -> str | None:
        """Why the part cannot be picked at `obj`, or None."""
        (x0, y0), (x1, y1) = self.cfg.pick_region
        x, y, z = (float(v) for v in obj)
        if not (x0 <= x <= x1 and y0 <= y <= y1):
            return f"the part lies at ({x:.3f}, {y:.3f}) m, outside the pick region {self.cfg.pick_region}"
        if not self._on_table(obj):
            return f"the part's centre is at z = {z:.3f} m, not resting on the table (expected {self.rest_z:.3f} m)"
        return None

    def _alarm(self, cycle: int, report: CycleReport, reason: str) -> None:
        report.alarm = reason
        self.rt.log.write("alarm", cycle=cycle, reason=reason, action=self.cfg.on_alarm)
        log.warning("alarm in cycle %d: %s (%s)", cycle, reason, self.cfg.on_alarm)
        if self.cfg.on_alarm == "skip":
            self.feeder.clear_part(cycle)
