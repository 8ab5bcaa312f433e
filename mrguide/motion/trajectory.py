"""Ruckig jerk-limited joint trajectories, streamed one control period at a time."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from ruckig import ControlInterface, InputParameter, OutputParameter, Result, Ruckig, RuckigError

from mrguide.robot import RobotSpec


class TrajectoryError(RuntimeError):
    """Ruckig rejected the input (target outside the position limits, non-finite values, ...)."""


#: Jerk limits of the retry after Ruckig fails on a numerical edge case (scaled by this, i.e. lowered).
EDGE_CASE_JERK_SCALE = 1.0 - 1e-9
#: A joint this close to its target, this slow and this little accelerated (rad, rad/s, rad/s^2) is at rest there:
#: what is left is floating-point residue of the last plan, which the retry clears.
RESIDUE = 1e-9


@dataclass
class JointSetpoint:
    """One control-period sample of the joint trajectory."""

    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    finished: bool


class JointStreamer:
    """Online trajectory generation: re-targetable at any cycle, continuous in position/velocity/acceleration."""

    def __init__(self, spec: RobotSpec, control_period: float = 0.004):
        if not control_period > 0:
            raise ValueError(f"control period must be > 0, got {control_period}")
        self.spec = spec
        self.control_period = control_period
        n = spec.dof
        self._otg = Ruckig(n, control_period)
        self._inp = InputParameter(n)
        self._out = OutputParameter(n)
        self._inp.max_velocity = spec.v_max.tolist()
        self._inp.max_acceleration = spec.a_max.tolist()
        self._inp.max_jerk = spec.j_max.tolist()
        self._inp.min_position = spec.q_lower.tolist()
        self._inp.max_position = spec.q_upper.tolist()
        self.reset(spec.q_home)

    def reset(self, q: np.ndarray, dq: np.ndarray | None = None, ddq: np.ndarray | None = None) -> None:
        """Restart from state (q, dq, ddq), holding q as target."""
        n = self.spec.dof
        q = np.asarray(q, dtype=float)
        self._otg.reset()  # forget the cached trajectory: the next update plans from this state
        self._inp.current_position = q.tolist()
        self._inp.current_velocity = (np.zeros(n) if dq is None else np.asarray(dq, float)).tolist()
        self._inp.current_acceleration = (np.zeros(n) if ddq is None else np.asarray(ddq, float)).tolist()
        self._inp.control_interface = ControlInterface.Position
        self._inp.target_position = q.tolist()
        self._inp.target_velocity = [0.0] * n
        self._inp.target_acceleration = [0.0] * n

    def set_target(self, q_target: np.ndarray) -> None:
        """New target configuration, reached at rest; motion continues smoothly from the current state."""
        q_target = np.asarray(q_target, dtype=float)
        if q_target.shape != (self.spec.dof,) or not np.all(np.isfinite(q_target)):
            raise TrajectoryError(f"trajectory target must be {self.spec.dof} finite values, got {q_target}")
        if not self.spec.within_limits(q_target):
            raise TrajectoryError(f"trajectory target {np.round(q_target, 4).tolist()} outside the joint limits")
        self._inp.control_interface = ControlInterface.Position
        self._inp.target_position = q_target.tolist()

    @contextlib.contextmanager
    def slowed(self, factor: float) -> Iterator[None]:
        """Within the block, the velocity, acceleration and jerk limits are `factor` (0 < factor <= 1) of the arm's:
        a move that carries what may be held badly."""
        if not 0.0 < factor <= 1.0:
            raise ValueError(f"a slowed move's factor must be in (0, 1], got {factor}")
        spec, i = self.spec, self._inp
        i.max_velocity, i.max_acceleration, i.max_jerk = (
            (x * factor).tolist() for x in (spec.v_max, spec.a_max, spec.j_max)
        )
        try:
            yield
        finally:
            i.max_velocity, i.max_acceleration, i.max_jerk = (x.tolist() for x in (spec.v_max, spec.a_max, spec.j_max))

    def brake(self) -> None:
        """Come to rest as fast as the limits allow (jerk-limited), wherever that is: the 'hold' reaction."""
        self._inp.control_interface = ControlInterface.Velocity
        self._inp.target_velocity = [0.0] * self.spec.dof
        self._inp.target_acceleration = [0.0] * self.spec.dof

    def _settle_residue(self) -> None:
        """Joints within RESIDUE of their target, velocity and acceleration are put exactly at rest on it."""
        i = self._inp
        q, dq, ddq, target = (
            np.array(x) for x in (i.current_position, i.current_velocity, i.current_acceleration, i.target_position)
        )
        rest = (np.abs(target - q) < RESIDUE) & (np.abs(dq) < RESIDUE) & (np.abs(ddq) < RESIDUE)
        if i.control_interface == ControlInterface.Position and rest.any():
            i.current_position = np.where(rest, target, q).tolist()
            i.current_velocity = np.where(rest, 0.0, dq).tolist()
            i.current_acceleration = np.where(rest, 0.0, ddq).tolist()

    def _update(self) -> Result:
        """Ruckig's update. Ruckig 0.19 throws on some exact inputs lying on a boundary between its profile
        types (from rest, -0.1200000000000001 -> 0 rad at 1.5 rad/s, 6 rad/s^2, 60 rad/s^3 throws "error in
        step 1"; a joint 1e-16 rad from its target at 2e-16 rad/s throws "error in step 2"); such a plan is
        retried once with the joints at rest on their targets within RESIDUE put exactly there and the jerk
        limits lowered by 1e-9, which moves the boundary. Any other failure raises TrajectoryError."""
        try:
            return self._otg.update(self._inp, self._out)
        except RuckigError:
            self._settle_residue()
            jerk = list(self._inp.max_jerk)
            self._inp.max_jerk = [j * EDGE_CASE_JERK_SCALE for j in jerk]
            try:
                return self._otg.update(self._inp, self._out)
            except RuckigError as exc:
                raise TrajectoryError(
                    f"Ruckig cannot plan from {np.round(self._inp.current_position, 4).tolist()} "
                    f"to {np.round(self._inp.target_position, 4).tolist()}: {exc}"
                ) from exc
            finally:
                self._inp.max_jerk = jerk

    def state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Current commanded (q, dq, ddq)."""
        i = self._inp
        return np.array(i.current_position), np.array(i.current_velocity), np.array(i.current_acceleration)

    def snapshot(self) -> tuple[list[float], ...]:
        """Full streamer state (current and target), for save/restore."""
        i = self._inp
        return (
            list(i.current_position),
            list(i.current_velocity),
            list(i.current_acceleration),
            list(i.target_position),
            [float(i.control_interface == ControlInterface.Velocity)],
        )

    def restore(self, snap: tuple[list[float], ...]) -> None:
        q, dq, ddq, target, braking = snap
        self.reset(np.array(q), np.array(dq), np.array(ddq))
        self._inp.target_position = list(target)
        if braking[0]:
            self.brake()

    def step(self) -> JointSetpoint:
        """Advance one control period and return the new setpoint; TrajectoryError if Ruckig cannot plan it."""
        result = self._update()
        if result not in (Result.Working, Result.Finished):
            raise TrajectoryError(f"Ruckig failed with {result}")
        out = self._out
        sp = JointSetpoint(
            np.array(out.new_position),
            np.array(out.new_velocity),
            np.array(out.new_acceleration),
            result == Result.Finished,
        )
        out.pass_to_input(self._inp)
        return sp


def point_to_point(spec: RobotSpec, q_from: np.ndarray, q_to: np.ndarray, control_period: float) -> list[np.ndarray]:
    """A jerk-limited move from rest at `q_from` to rest at `q_to`, one setpoint per control period (ends at `q_to`)."""
    streamer = JointStreamer(spec, control_period)
    streamer.reset(q_from)
    streamer.set_target(q_to)
    path = []
    while True:
        sp = streamer.step()
        path.append(sp.q)
        if sp.finished:
            return path
