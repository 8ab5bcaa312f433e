"""Safety supervisor of the deploy runtime: what is watched, how each event is answered, and counts.

Reactions, mildest first:
- CLAMP: the target is moved (into the workspace box, or by a rule of the cell: the descent and lift rules, the seal search);
  the episode goes on.
- LAST_KNOWN: the decision uses the last valid value (the object pose) and the episode goes on.
- HOLD: the arm brakes to rest on a jerk-limited ramp (Ruckig) and keeps its position; the episode goes on.
- ABORT: the arm brakes to rest and the episode ends (the run continues with the next one).
- QUICK_STOP: the drives execute their CiA 402 quick stop; the episode ends and the run stops.

Every check fails closed: a comparison with NaN (in a limit or in a measurement) trips it.
"""

from __future__ import annotations

import enum
import logging
import math
import threading
import time
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated

import numpy as np

from mrguide.config import Range, check_ranges
from mrguide.robot import RobotSpec

log = logging.getLogger(__name__)


class Reaction(str, enum.Enum):
    CLAMP = "clamp"
    LAST_KNOWN = "last_known"
    HOLD = "hold"
    ABORT = "abort"
    QUICK_STOP = "quick_stop"


class Event(str, enum.Enum):
    """Everything the supervisor reacts to, with its fixed reaction in `REACTIONS`."""

    WORKSPACE = "workspace"  # policy target outside the workspace box
    NON_FINITE_ACTION = "non_finite_action"  # NaN/inf from the policy
    INVALID_ACTION = "invalid_action"  # an action of the wrong shape from the policy
    IK_FAILURE = "ik_failure"  # target not reachable with the tool down
    IK_FAILURES_REPEATED = "ik_failures_repeated"  # several in a row
    POSE_UNAVAILABLE = "pose_unavailable"  # no object pose this decision (the last one is used)
    POSE_LOST = "pose_lost"  # no object pose for more decisions in a row than allowed
    JOINT_LIMIT = "joint_limit"  # a setpoint outside position/velocity/acceleration limits
    TRAJECTORY = "trajectory"  # the trajectory generator cannot plan the next setpoint
    FOLLOWING_ERROR = "following_error"  # measured joints too far from the commanded ones
    DRIVE_FAULT = "drive_fault"  # EMCY, heartbeat loss, lost feedback, bus error (latched by the driver)
    VACUUM_LOST = "vacuum_lost"  # part lost during lift or transport (a drop)
    VACUUM_NOT_OK = "vacuum_not_ok"  # a lift asked before the part was reported gripped: the arm does not rise
    BREAK_AWAY = "break_away"  # the lift's first millimetres slowed (lift_rule.py)
    HOLD_IN_TRANSIT = "hold_in_transit"  # a release asked in the lift or transport: the vacuum stays on (lift_rule.py)
    DESCENT = "descent"  # the cup kept off the part until over it, and not slid while down (descent_rule.py)
    CARRY = "carry"  # a held part kept above the table until over its goal (descent_rule.py)
    RESEAT = "reseat"  # a cup pressed without a seal re-seated at the next point of the search (seal_search.py)
    STALL = "stall"  # the decision loop stopped feeding setpoints (watchdog)
    INTERRUPT = "interrupt"  # Ctrl-C


REACTIONS: dict[Event, Reaction] = {
    Event.WORKSPACE: Reaction.CLAMP,
    Event.NON_FINITE_ACTION: Reaction.ABORT,
    Event.INVALID_ACTION: Reaction.ABORT,
    Event.IK_FAILURE: Reaction.HOLD,
    Event.IK_FAILURES_REPEATED: Reaction.ABORT,
    Event.POSE_UNAVAILABLE: Reaction.LAST_KNOWN,
    Event.POSE_LOST: Reaction.ABORT,
    Event.JOINT_LIMIT: Reaction.QUICK_STOP,
    Event.TRAJECTORY: Reaction.QUICK_STOP,
    Event.FOLLOWING_ERROR: Reaction.QUICK_STOP,
    Event.DRIVE_FAULT: Reaction.QUICK_STOP,
    Event.VACUUM_LOST: Reaction.ABORT,
    Event.VACUUM_NOT_OK: Reaction.CLAMP,
    Event.BREAK_AWAY: Reaction.CLAMP,
    Event.HOLD_IN_TRANSIT: Reaction.CLAMP,
    Event.DESCENT: Reaction.CLAMP,
    Event.CARRY: Reaction.CLAMP,
    Event.RESEAT: Reaction.CLAMP,
    Event.STALL: Reaction.QUICK_STOP,
    Event.INTERRUPT: Reaction.QUICK_STOP,
}


@dataclass(frozen=True)
class SafetyConfig:
    """Limits of the supervisor ([safety] in a TOML config); each must be finite and in its range."""

    #: in [1e-4, 1]; the drives' own window (0x6065) is the same by default
    following_error: Annotated[float, Range(1e-4, 1.0, " rad")] = 0.05
    max_consecutive_ik_failures: Annotated[int, Range(1, 1000)] = 3  # in [1, 1000]
    #: s without a new setpoint while moving → quick stop; in [0.01, 10]
    stall_timeout: Annotated[float, Range(0.01, 10.0, " s")] = 0.25
    #: relative slack on velocity/acceleration checks; in [0, 0.1]
    limit_tolerance: Annotated[float, Range(0.0, 0.1)] = 1e-6

    def __post_init__(self) -> None:
        check_ranges(self, "safety")


class Supervisor:
    """Counts and logs events and says how to react; `check_setpoint` guards every streamed setpoint."""

    def __init__(
        self, spec: RobotSpec, cfg: SafetyConfig, on_event: Callable[[Event, Reaction, str], None] | None = None
    ):
        self.spec, self.cfg = spec, cfg
        self.counts: Counter[str] = Counter()
        self.on_event = on_event
        self._ik_failures = 0

    def report(self, event: Event, detail: str) -> Reaction:
        reaction = REACTIONS[event]
        self.counts[event.value] += 1
        (log.info if reaction in (Reaction.CLAMP, Reaction.LAST_KNOWN) else log.warning)(
            "safety: %s -> %s: %s", event.value, reaction.value, detail
        )
        if self.on_event:
            self.on_event(event, reaction, detail)
        return reaction

    def ik_result(self, ok: bool, detail: str = "") -> Reaction | None:
        """Track IK outcomes; a failure holds, several in a row abort."""
        if ok:
            self._ik_failures = 0
            return None
        self._ik_failures += 1
        if self._ik_failures >= self.cfg.max_consecutive_ik_failures:
            return self.report(Event.IK_FAILURES_REPEATED, f"{self._ik_failures} IK failures in a row: {detail}")
        return self.report(Event.IK_FAILURE, detail)

    def check_setpoint(self, q: np.ndarray, dq: np.ndarray, ddq: np.ndarray) -> str | None:
        """Why a setpoint violates the position/velocity/acceleration limits, or None."""
        s, tol = self.spec, 1 + self.cfg.limit_tolerance
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(dq)) and np.all(np.isfinite(ddq))):
            return "non-finite setpoint"
        if not s.within_limits(q, tol=1e-9):
            return f"position {np.round(q, 4).tolist()} outside the joint limits"
        if not np.all(np.abs(dq) <= s.v_max * tol):
            return f"velocity {np.round(dq, 3).tolist()} above v_max"
        if not np.all(np.abs(ddq) <= s.a_max * tol):
            return f"acceleration {np.round(ddq, 3).tolist()} above a_max"
        return None

    def check_following(self, error: float, joint: int = 0) -> str | None:
        """Why the measured joints are too far from the setpoints (`error`: rad, of the furthest joint, index
        `joint`), or None."""
        if not error <= self.cfg.following_error:
            name = self.spec.joint_names[joint]
            return f"{name} measured {error:.4f} rad from its setpoints (limit {self.cfg.following_error} rad)"
        return None


class Watchdog:
    """A thread that calls `on_stall` if `feed()` is not called for `timeout` seconds while armed."""

    def __init__(self, timeout: float, on_stall: Callable[[float], None]):
        if not (math.isfinite(timeout) and timeout > 0):
            raise ValueError(f"stall timeout must be a finite number of seconds > 0, got {timeout}")
        self.timeout = timeout
        self.on_stall = on_stall
        self._last = time.monotonic()
        self._armed = False
        self._fired = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="deploy-watchdog", daemon=True)

    def start(self) -> None:
        self._thread.start()

    def feed(self) -> None:
        self._last = time.monotonic()

    def arm(self, armed: bool) -> None:
        self._last = time.monotonic()
        self._armed = armed
        self._fired = False

    @property
    def fired(self) -> bool:
        return self._fired

    @property
    def alive(self) -> bool:
        """Whether the watchdog thread runs (the runtime stops if it does not: no stall supervision)."""
        return self._thread.is_alive()

    def _run(self) -> None:
        while not self._stop.wait(self.timeout / 5):
            age = time.monotonic() - self._last
            if self._armed and not self._fired and not age <= self.timeout:
                self._fired = True
                self.on_stall(age)

    def close(self) -> None:
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
