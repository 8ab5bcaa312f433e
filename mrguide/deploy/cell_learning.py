"""On-cell learning's actor side: the runtime's decisions as transitions for a learner, and the learner's newer
policies taken in between episodes. numpy only: the learner lives in `policies`, the command joining them above both.

**A transition is what the cell sensed.** The observation is the one the runtime built (the TCP from the drives'
feedback, g from the vacuum command, the part from the pose source, filtered and corrected as the runtime uses it),
the action the one the cell carried out (the policy's after the cell's rules — lift rules, hold in transit, seal
search — clipped to the action box as the decision step clamps it), the reward and the outcome the task model's,
judged on the next decision's sensed state. No simulator's state enters: in a dry run only the scorer reads it.
An episode the supervisor ended (pose lost, aborted, a safety stop) leaves its last action without a transition:
nothing the task did ended it, and what followed was not the policy's.

**A newer policy is a policy file.** The learner's weights reach the runtime as a policy file of a new version,
loaded by `ExportedPolicy.load` with every check a file on the robot gets (format, arm, shapes, finite actions over
the workspace), between episodes only: an episode runs on one policy. A file that fails a check is logged and
skipped; the runtime goes on with the policy it has.

**A person may step in** (`interventions`): at the start of an episode, the episode is played by the expert their
marks build and its transitions are expert data (`deploy.interventions`).
"""

from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

import numpy as np

from mrguide.config import Range, check_ranges
from mrguide.deploy.interventions import (
    CellStart,
    Demonstration,
    InterventionCounts,
    Interventions,
    Write,
    take_intervention,
)
from mrguide.deploy.policy import ExportedPolicy, PolicyFileError
from mrguide.deploy.version_gate import VersionGate
from mrguide.robot import RobotSpec
from mrguide.task import Outcome, TaskConfig

log = logging.getLogger(__name__)

#: The success rate the annotation page shows is over this many cycles.
RECENT_CYCLES = 20


@dataclass(frozen=True)
class LearningConfig:
    """[deploy.learning]: how the cell explores while it learns (`mrguide deploy --cycles N --learn RUN_DIR`)."""

    #: std of the Gaussian noise on every action while learning on the cell (normalized units: 0.02 is about 5 mm
    #: of the shipped workspace box), up to 0.1. None by default, measured: 0.1 (training's) jittered the cup
    #: centimetres over the part while it pressed and a drive faulted on following error within four cycles; 0.02
    #: kept the TCP from resting, so the seal search never started, and 5 mm is the seal's whole window: 17 of 33
    #: parts placed against 92 of 100 frozen (docs/results: learning on the cell). The learner's updates explore.
    exploration: Annotated[float, Range(0.0, 0.1)] = 0.0
    #: episodes a newer version acts on trial: kept once it has placed this many parts in a row (sensed), dropped at
    #: its first failure (`version_gate`); 0 takes each newer version at once, which made one of three policies
    #: trained at exploration 0.1 worse (97 of the last 100 parts against 99 of 100 frozen; docs/results: learning on
    #: the cell, and its history).
    trial: Annotated[int, Range(0, 1000)] = 10

    def __post_init__(self) -> None:
        check_ranges(self, "deploy.learning")


@dataclass(frozen=True)
class Transition:
    """One decision of the cell: s, a (as carried out), r, s', whether the task ended there, a person's (ζ = 1)."""

    obs: np.ndarray
    action: np.ndarray
    reward: float
    next_obs: np.ndarray
    done: bool
    expert: bool = False


class TransitionTap:
    """Pairs each decision's action with the next decision's judgement and hands the transition to `sink`.

    The runtime calls `acted` when it has decided (the action as it will be carried out) and `judged` with the
    next decision's sensed observation, reward and outcome (None while the episode goes on); `reset` at the start
    of an episode drops an action left unjudged."""

    def __init__(self, sink: Callable[[Transition], None]):
        self.sink = sink
        self.expert = False  # the actions are a person's (an intervention): stored as expert data
        self._pending: tuple[np.ndarray, np.ndarray, bool] | None = None

    def reset(self) -> None:
        self._pending = None

    def acted(self, obs: np.ndarray, action: np.ndarray) -> None:
        a = np.asarray(action, dtype=np.float32)
        if a.shape != (4,) or not np.all(np.isfinite(a)):  # refused by the decision step: nothing carried out
            self._pending = None
            return
        self._pending = (np.array(obs, dtype=np.float32), np.clip(a, -1.0, 1.0), self.expert)

    def judged(self, obs: np.ndarray, reward: float | None, outcome: Outcome | None) -> None:
        pending, self._pending = self._pending, None
        if pending is None or reward is None:
            return
        done = outcome is not None and outcome.terminated
        self.sink(Transition(pending[0], pending[1], float(reward), np.array(obs, dtype=np.float32), done, pending[2]))


class PolicyVersions:
    """The policy the runtime acts with, the version it keeps, and the newest version a learner has offered.

    Callable as a policy. `offer` may come from any thread; `take_newest`, between episodes, loads the newest
    offered file (checked as `ExportedPolicy.load` checks a file for the robot) and acts with it on trial;
    `episode_end` judges the trial (`version_gate`: kept after `trial` episodes in a row in success, dropped at a
    failure, the kept version acting again)."""

    def __init__(
        self,
        policy: ExportedPolicy,
        robot: RobotSpec,
        task: TaskConfig,
        learning: LearningConfig = LearningConfig(),
        seed: int = 0,
        on_change: Callable | None = None,
        version: int = 0,
    ):
        """`policy` is version `version`, the one kept; `learning.exploration`: std of the Gaussian noise added to
        every action (normalized units, clipped to the box); the cell's rules and limits apply to the noisy action
        as to any."""
        self.policy, self.version, self.robot, self.task = policy, version, robot, task
        self.exploration, self.rng = learning.exploration, np.random.default_rng(seed)
        self.gate = VersionGate(learning.trial)
        self.on_change = on_change  # called with (version, path, error or None) when a version is taken or refused
        self._kept = (policy, version)
        self._offered: tuple[int, Path] | None = None
        self._tried = version
        self._lock = threading.Lock()

    @property
    def kept_version(self) -> int:
        return self._kept[1]

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        action = self.policy(obs)
        if self.exploration > 0:
            noise = self.rng.normal(0.0, self.exploration, action.shape)
            action = np.clip(action + noise, -1.0, 1.0).astype(action.dtype)
        return action

    def offer(self, version: int, path: str | Path) -> None:
        """A learner's newer policy file; ignored unless newer than what was offered before."""
        with self._lock:
            if self._offered is None or version > self._offered[0]:
                self._offered = (version, Path(path))

    def take_newest(self) -> int:
        """Between episodes: the version this episode acts with — the one on trial while its trial goes on, else the
        newest offered version not yet tried when the gate lets it be tried, else the kept one."""
        with self._lock:
            offered = self._offered
        if self.gate.trying or not self.gate.may_try() or offered is None or offered[0] <= self._tried:
            return self.version
        version, path = offered
        self._tried = version
        try:
            policy = ExportedPolicy.load(path, self.robot, self.task)
            if policy.decision_period != self.policy.decision_period:
                raise PolicyFileError(f"{path}: decision period {policy.decision_period} s, the runtime's differs")
        except (PolicyFileError, OSError) as exc:
            log.warning("policy version %d refused, acting on with version %d: %s", version, self.version, exc)
            if self.on_change:
                self.on_change(version, path, str(exc))
            return self.version
        self.policy, self.version = policy, version
        self.gate.start()
        if not self.gate.trying:
            self._kept = (policy, version)
        if self.on_change:
            self.on_change(version, path, None)
        return version

    def episode_end(self, outcome: Outcome) -> str | None:
        """An episode the policy played ended: the trial's verdict ("kept", "dropped") or None."""
        verdict = self.gate.judge(outcome)
        if verdict == "kept":
            self._kept = (self.policy, self.version)
        elif verdict == "dropped":
            log.info(
                "policy version %d dropped (%s): version %d acts again", self.version, outcome.value, self.kept_version
            )
            self.policy, self.version = self._kept
        return verdict


@dataclass
class LearningActor:
    """What the runtime calls while it learns on the cell: a new episode (the transitions so far handed on by
    `between`, the newest policy taken in, an unjudged action dropped, a person's intervention taken up), each
    decision's action (`__call__`: the runtime's policy), each judgement (`tap`)."""

    versions: PolicyVersions
    tap: TransitionTap
    #: called between episodes, before the newest policy is taken: the learner's side sends what the tap gathered
    #: and offers the versions it has (nothing runs on the cell meanwhile: the arm stands, the watchdog is off)
    between: Callable[[], None] | None = None
    #: a person stepping in from the annotation page (`deploy --annotate`), taken up at an episode's start
    interventions: Interventions | None = None
    counts: InterventionCounts = field(default_factory=InterventionCounts)
    _expert: Demonstration | None = field(default=None, init=False)
    _placed: deque[bool] = field(default_factory=lambda: deque(maxlen=RECENT_CYCLES), init=False)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """The action for `obs`: the person's expert's in an episode they took over, else the policy's."""
        if self._expert is not None:
            action = self._expert.act(obs)
            if action is not None:
                return action
            log.warning("the intervention's expert has no action: the policy plays the rest of the episode")
            self._expert, self.tap.expert = None, False
        return self.versions(obs)

    def episode_start(self, episode: int, write: Write, sense: Callable[[], CellStart]) -> int:
        """The policy version this episode acts with (written to the run log as `policy_version`); a person who asked
        to step in is asked for marks now, the arm at rest and holding no part (`interventions`)."""
        self.tap.reset()
        if self.between is not None:
            self.between()
        version = self.versions.take_newest()
        write("policy_version", episode=episode, version=version, on_trial=self.versions.gate.trying)
        self._expert = None
        if self.interventions is not None:
            self._expert = take_intervention(self.interventions, self.counts, episode, sense, write)
        self.tap.expert = self._expert is not None
        return version

    def episode_end(self, episode: int, outcome: Outcome, write: Write) -> None:
        """An episode ended: the version on trial judged by it (a person's episode judges nothing); a verdict is
        written to the run log as `policy_trial`."""
        if self._expert is not None:
            return
        version = self.versions.version
        if (verdict := self.versions.episode_end(outcome)) is not None:
            write("policy_trial", episode=episode, version=version, verdict=verdict, acting=self.versions.version)

    def cycle_done(self, cycle: int, placed: bool) -> None:
        """A cycle ended: the page's status (the cycle, the version, success over the last RECENT_CYCLES cycles)."""
        self._placed.append(placed)
        if self.interventions is not None:
            self.interventions.publish(
                cycle=cycle,
                version=self.versions.version,
                success_rate=sum(self._placed) / len(self._placed),
                interventions=self.counts.played,
                person_interventions=self.counts.played,
                skipped=self.counts.fell_back,
            )
