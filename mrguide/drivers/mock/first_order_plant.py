"""A first-order plant: each joint lags its position target, the cup's vacuum lags the valve state.

Good enough to exercise the bus, the CSP streaming and the gripper signals without a physics engine.
All parameter values are assumptions, not datasheet figures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mrguide.plant import Plant


@dataclass(frozen=True)
class FirstOrderParams:
    """Time constants (s) and vacuum levels (kPa below atmosphere)."""

    #: Closed position loop of a joint drive modelled as a first-order lag.
    joint_time_constant: float = 0.005
    #: Level reached with a part sealing the cup (ejectors of the LEMCOM class reach roughly 85 %).
    sealed_level_kpa: float = 75.0
    #: Level reached with the cup open to air.
    open_level_kpa: float = 8.0
    evacuation_time_constant: float = 0.05
    #: Vacuum decay with the valve closed and no blow-off.
    release_time_constant: float = 0.3
    blow_off_time_constant: float = 0.02
    #: A part in contact is held once the level exceeds this...
    hold_level_kpa: float = 20.0
    #: ...and falls off a held cup when the level drops below this.
    drop_level_kpa: float = 10.0


class FirstOrderPlant(Plant):
    """Joint i: q_i += (target_i - q_i) * (1 - exp(-dt / tau)); vacuum level likewise toward its set level."""

    def __init__(self, q0: np.ndarray, params: FirstOrderParams | None = None) -> None:
        self.params = params or FirstOrderParams()
        self._q = np.array(q0, dtype=float)
        if self._q.ndim != 1 or not np.all(np.isfinite(self._q)):
            raise ValueError(f"q0 must be a finite 1-D array of joint positions, got {q0!r}")
        self._v = np.zeros_like(self._q)
        self._target = self._q.copy()
        self._vacuum_on = False
        self._blow_off = False
        self._level = 0.0
        self._leak = 0.0
        self._contact = False
        self._held = False

    @property
    def dof(self) -> int:
        return len(self._q)

    def step(self, dt: float) -> None:
        p = self.params
        alpha = 1.0 - math.exp(-dt / p.joint_time_constant)
        q_new = self._q + (self._target - self._q) * alpha
        self._v = (q_new - self._q) / dt
        self._q = q_new
        self._step_vacuum(dt)

    def _step_vacuum(self, dt: float) -> None:
        p = self.params
        if self._blow_off:
            goal, tau = 0.0, p.blow_off_time_constant
        elif self._vacuum_on:
            goal = (p.sealed_level_kpa if self._contact else p.open_level_kpa) * (1.0 - self._leak)
            tau = p.evacuation_time_constant
        else:
            goal, tau = 0.0, p.release_time_constant
        self._level += (goal - self._level) * (1.0 - math.exp(-dt / tau))
        if self._contact and self._level >= p.hold_level_kpa:
            self._held = True
        if self._held and self._level < p.drop_level_kpa:
            self._held = False
            self._contact = False

    def set_joint_targets(self, q: np.ndarray) -> None:
        self._target = np.array(q, dtype=float)

    def joint_positions(self) -> np.ndarray:
        return self._q.copy()

    def joint_velocities(self) -> np.ndarray:
        return self._v.copy()

    def set_vacuum(self, on: bool, blow_off: bool) -> None:
        self._vacuum_on = on
        self._blow_off = blow_off

    def vacuum_level_kpa(self) -> float:
        return self._level

    def part_present(self) -> bool:
        return self._contact

    def place_part(self) -> None:
        """Put a part in contact with the suction cup (as if the arm had moved onto it)."""
        self._contact = True

    def set_vacuum_leak(self, fraction: float) -> None:
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"leak fraction must lie in [0, 1], got {fraction}")
        self._leak = fraction
