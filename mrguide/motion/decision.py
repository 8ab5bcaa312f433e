"""The decision step: one policy decision, the same code in the twin (training) and on the robot.

    observation ─▶ policy ─▶ action ─▶ check (shape, finite) ─▶ clamp to [-1, 1] (counted) ─▶ workspace box
    ─▶ Pinocchio IK warm-started at the measured joints (failure: hold, i.e. brake to rest) ─▶ Ruckig target
    ... one decision period of setpoints, executed by whoever owns the arm (twin servos or CAN drives) ...
    measured joints ─▶ FK ─▶ tcp; vacuum, part signal, object ─▶ task model ─▶ phase, reward, outcome ─▶ observation

`PickPlaceEnv.step` (twin/env.py) and `Runtime.run_episode` (deploy/runtime.py) both drive a `DecisionStep`:
`act` before the period, `judge` and `observe` after it. What only a robot has (the safety supervisor's
reactions: aborting after repeated IK failures, quick stops, the run log) stays in the runtime; what only
a simulator has (physics) stays in the env. No PyBullet, no torch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mrguide.motion.kinematics import IKError, Kinematics
from mrguide.motion.trajectory import JointStreamer
from mrguide.robot import RobotSpec
from mrguide.task import ACT_DIM, StepResult, TaskConfig, observation, progress, task_step

#: What `ActionError.kind` says: the action's shape is wrong, or it holds NaN/inf.
BAD_SHAPE, NON_FINITE = "shape", "non_finite"


class ActionError(ValueError):
    """An action that cannot be executed; `kind` is BAD_SHAPE or NON_FINITE."""

    def __init__(self, message: str, kind: str):
        super().__init__(message)
        self.kind = kind


def check_action(action: np.ndarray) -> np.ndarray:
    """The action as a float array of shape (4,), or ActionError (wrong shape, NaN or inf)."""
    a = np.asarray(action, dtype=float)
    if a.shape != (ACT_DIM,):
        raise ActionError(f"action must have shape ({ACT_DIM},), got {a.shape}", BAD_SHAPE)
    if not np.all(np.isfinite(a)):
        raise ActionError(f"action contains NaN or inf: {a.tolist()}", NON_FINITE)
    return a


@dataclass(frozen=True)
class Command:
    """What one decision asks of the arm."""

    #: TCP target in the base frame (m): the clamped action mapped into the workspace box.
    target: np.ndarray
    #: Vacuum command (g' > 0 closes).
    vacuum: bool
    #: Whether the position part of the action was outside [-1, 1] and clamped (the one clamp rule).
    clamped: bool
    #: Joint target handed to the trajectory generator; None when IK failed and the arm holds (brakes).
    q_target: np.ndarray | None
    #: Why IK failed, or None.
    ik_error: str | None = None


@dataclass
class DecisionState:
    """The decision step's episode state (restorable: see `DecisionStep.snapshot`)."""

    phase: int = 0
    t: int = 0  # decisions judged so far in this episode
    clamped: int = 0  # decisions whose action was clamped
    ik_failures: int = 0  # decisions whose IK failed (the arm held)


class DecisionStep:
    """Clamp → IK → trajectory target, and task step → phase, reward, outcome, for one arm and task."""

    def __init__(self, spec: RobotSpec, task: TaskConfig, control_period: float):
        self.spec, self.task = spec, task
        self.workspace = spec.workspace
        self.kin = Kinematics(spec)
        self.streamer = JointStreamer(spec, control_period)
        self.state = DecisionState()

    @property
    def phase(self) -> int:
        return self.state.phase

    def reset(self, q: np.ndarray) -> None:
        """New episode: phase 0, counters zero, the trajectory at rest at the joint configuration `q`."""
        self.streamer.reset(q)
        self.state = DecisionState()

    # -- before the decision period ------------------------------------------------------------------
    def act(self, action: np.ndarray, q_measured: np.ndarray) -> Command:
        """Check, clamp and solve `action`, and retarget the trajectory; ActionError for a bad action.

        The clamp rule: each component of the action's position part is clipped to [-1, 1] and the result
        mapped into the workspace box (so the target never leaves it); a clipped action is counted. IK is
        warm-started at the measured joints; when it fails the arm holds (the trajectory brakes to rest
        wherever it is) and the failure is counted.
        """
        a = check_action(action)
        clipped = np.clip(a, -1.0, 1.0)
        clamped = bool(np.any(clipped[:3] != a[:3]))
        self.state.clamped += int(clamped)
        target = self.workspace.to_cartesian(clipped[:3])
        vacuum = bool(clipped[3] > 0)
        try:
            q_target = self.kin.ik(target, q_measured)
        except IKError as exc:
            self.state.ik_failures += 1
            self.streamer.brake()
            return Command(target, vacuum, clamped, None, str(exc))
        self.streamer.set_target(q_target)
        return Command(target, vacuum, clamped, q_target)

    # -- after the decision period -------------------------------------------------------------------
    def tcp(self, q_measured: np.ndarray) -> np.ndarray:
        """TCP position (m) at the measured joints (forward kinematics)."""
        return self.kin.tcp_position(q_measured)

    def judge(self, tcp: np.ndarray, g: int, part_present: bool, obj: np.ndarray, goal: np.ndarray) -> StepResult:
        """The task model on the state the decision reached: reward, next phase, outcome (the one success rule)."""
        res = task_step(self.task, self.state.phase, tcp, g, part_present, obj, goal, self.state.t)
        self.state.t += 1
        self.state.phase = res.phase
        return res

    def observe(self, tcp: np.ndarray, g: int, obj: np.ndarray, goal: np.ndarray, success: bool = False) -> np.ndarray:
        """The policy's observation in the current phase (φ = 1 after a success)."""
        return observation(tcp, g, progress(self.state.phase, success), obj, goal)

    # -- save and restore (the twin's episode replays) -----------------------------------------------
    def snapshot(self) -> tuple[DecisionState, tuple[list[float], ...]]:
        s = self.state
        return DecisionState(s.phase, s.t, s.clamped, s.ik_failures), self.streamer.snapshot()

    def restore(self, snap: tuple[DecisionState, tuple[list[float], ...]]) -> None:
        state, streamer = snap
        self.state = DecisionState(state.phase, state.t, state.clamped, state.ik_failures)
        self.streamer.restore(streamer)
