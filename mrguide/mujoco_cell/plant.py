"""The MuJoCo cell as the plant behind the simulated CANopen drives and vacuum generator.

`MujocoPlant` implements the driver layer's `Plant` as `TwinPlant` does for PyBullet: the simulated cobot calls
it once per SYNC from its CAN thread, and each call runs the physics steps of one control period toward the
received CSP targets (interpolated linearly between SYNCs, as a CiA 402 drive interpolates). Every access takes
one lock (the run's pose sources read the part from other threads).

The vacuum at the cup: the generator's level follows a first-order lag toward the level the cell's seal gives
(`mrguide.seal`, the same as the twin's: the sealed level while the cup's lip rests whole on a face of the part,
less what the lip leaks where it hangs past the face's edge, the open-cup level where it does not rest on one),
and decays with the valve closed (time constants and levels: the drivers' simulated generator,
`FirstOrderParams`). The level drives the cup's adhesion actuator, so the part is held by F = Δp · A and
nothing else: a lift that asks more of it tears the part off. Once sealed and held, a weld keeps the part where it
sealed until its load passes what the level holds (`seal_weld`: MuJoCo's contacts alone let a held part creep).
"""

from __future__ import annotations

import math
import threading

import mujoco
import numpy as np

from mrguide import seal
from mrguide.cell_layout import CupConfig
from mrguide.drivers.mock.first_order_plant import FirstOrderParams
from mrguide.mujoco_cell.config import MujocoCellConfig
from mrguide.mujoco_cell.model import build_cell
from mrguide.mujoco_cell.seal_weld import SealWeld
from mrguide.parts import PARTS, Part
from mrguide.plant import CellPlant
from mrguide.robot import RobotSpec


class MujocoPlant(CellPlant):
    """The MuJoCo cell: arm, table, one part (`mrguide.parts`) and a suction cup, advanced one SYNC period at a time."""

    def __init__(
        self,
        spec: RobotSpec,
        cfg: MujocoCellConfig | None = None,
        part: Part = PARTS["block"],
        vacuum: FirstOrderParams | None = None,
        cup: CupConfig | None = None,
    ):
        self.spec, self.cfg = spec, cfg or MujocoCellConfig()
        self.vacuum = vacuum or FirstOrderParams()
        self.cell = build_cell(spec, self.cfg, part, cup or CupConfig())
        self.model, self.data = self.cell.model, mujoco.MjData(self.cell.model)
        self.boxes = part.boxes
        self.lock = threading.Lock()
        self.data.qpos[self.cell.arm_qpos] = spec.q_home
        mujoco.mj_forward(self.model, self.data)
        self._target = np.array(spec.q_home, dtype=float)
        self._prev_target = self._target.copy()
        self._vacuum_on = self._blow_off = False
        self._level = 0.0
        self._leak = 0.0
        self.goal = np.zeros(3)
        self.weld = SealWeld(self.model, self.data, self.cell)
        self._reached = self.level_reached()  # kPa the generator reaches through the lip as it is
        self._lips, self._part = set(self.cell.lip_geoms.tolist()), set(self.cell.part_geoms.tolist())

    @property
    def dof(self) -> int:
        return self.spec.dof

    # -- the Plant interface ------------------------------------------------------------------------------
    def step(self, dt: float) -> None:
        n = round(dt / self.model.opt.timestep)
        if n < 1 or abs(n * self.model.opt.timestep - dt) > 1e-9:
            raise ValueError(
                f"the MuJoCo cell steps {self.model.opt.timestep} s; a SYNC period of {dt} s is not a multiple"
            )
        with self.lock:
            c, d = self.cell, self.data
            dq = (self._target - self._prev_target) / dt
            for i in range(1, n + 1):
                d.ctrl[c.position_actuators] = self._prev_target + (self._target - self._prev_target) * (i / n)
                d.ctrl[c.velocity_actuators] = dq
                self._step_vacuum(self.model.opt.timestep)
                d.ctrl[c.cup_actuator] = 0.0 if self.weld.active else self._level  # the weld alone holds
                mujoco.mj_step(self.model, d)
                self._hold_or_release()
            self._prev_target = self._target.copy()

    def set_joint_targets(self, q: np.ndarray) -> None:
        self._target = np.asarray(q, dtype=float).copy()

    def joint_positions(self) -> np.ndarray:
        with self.lock:
            return self.data.qpos[self.cell.arm_qpos].copy()

    def joint_velocities(self) -> np.ndarray:
        with self.lock:
            return self.data.qvel[self.cell.arm_dof].copy()

    def set_vacuum(self, on: bool, blow_off: bool) -> None:
        with self.lock:
            self._vacuum_on, self._blow_off = bool(on), bool(blow_off)

    def vacuum_level_kpa(self) -> float:
        with self.lock:
            return self._level

    def part_present(self) -> bool:
        """The part touches the cup (welded to it, or in contact with the lip)."""
        with self.lock:
            return self.weld.active or self._cup_touches_part()

    def set_vacuum_leak(self, fraction: float) -> None:
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"leak fraction must be in [0, 1], got {fraction}")
        with self.lock:
            self._leak = float(fraction)

    # -- the cell, for dry runs and judges ---------------------------------------------------------------
    def place_objects(self, obj: np.ndarray, goal: np.ndarray) -> None:
        """The part at rest at `obj` (upright), the goal at `goal`; the vacuum off, the arm left where it is."""
        with self.lock:
            c, d = self.cell, self.data
            self._vacuum_on = self._blow_off = False
            self._level = 0.0
            self.weld.release()
            d.qpos[c.part_qpos : c.part_qpos + 3] = obj
            d.qpos[c.part_qpos + 3 : c.part_qpos + 7] = (1.0, 0.0, 0.0, 0.0)
            d.qvel[c.part_dof : c.part_dof + 6] = 0.0
            mujoco.mj_forward(self.model, d)
            self._reached = self.level_reached()
            self.goal = np.asarray(goal, dtype=float).copy()

    def object_position(self) -> np.ndarray:
        with self.lock:
            return self.data.xpos[self.cell.part_body].copy()

    def view(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What a camera sees, read at one instant: part position, quaternion (x, y, z, w), true joints."""
        with self.lock:
            w, x, y, z = self.data.xquat[self.cell.part_body]
            return self.data.xpos[self.cell.part_body].copy(), np.array([x, y, z, w]), self.joint_positions_unlocked()

    def joint_positions_unlocked(self) -> np.ndarray:
        return self.data.qpos[self.cell.arm_qpos].copy()

    def tcp_position(self) -> np.ndarray:
        with self.lock:
            return self.data.xpos[self.cell.tcp_body].copy()

    # -- the vacuum ------------------------------------------------------------------------------------
    def _step_vacuum(self, dt: float) -> None:
        p = self.vacuum
        if self._blow_off:
            goal, tau = 0.0, p.blow_off_time_constant
        elif self._vacuum_on:
            goal = self._reached * (1.0 - self._leak)
            tau = p.evacuation_time_constant
        else:
            goal, tau = 0.0, p.release_time_constant
        self._level += (goal - self._level) * (1.0 - math.exp(-dt / tau))

    def _hold_or_release(self) -> None:
        """The seal's weld (`seal_weld`): made as the lip seals on the part, released when the load passes what
        the vacuum holds or the vacuum is off. While it holds, the lip stays where it sealed, and so does the level
        its seal reaches (`_reached`)."""
        if not self.weld.active:
            self._reached = self.level_reached()
        sealed = self._reached > self.vacuum.open_level_kpa  # the lip rests on a face, whole or leaking past its edge
        on = self._vacuum_on and not self._blow_off
        touching = self.weld.active or (on and sealed and self._cup_touches_part())  # the contacts only when it counts
        self.weld.update(self._level, self.vacuum.hold_level_kpa, on, sealed, touching)

    def _cup_touches_part(self) -> bool:
        d, lips, part = self.data, self._lips, self._part
        for i in range(d.ncon):
            a, b = int(d.contact.geom1[i]), int(d.contact.geom2[i])
            if (a in part and b in lips) or (b in part and a in lips):
                return True
        return False

    def _lip(self) -> tuple[np.ndarray, np.ndarray]:
        """The lip's centre and the cup's axis (out of the lip) in the part's frame."""
        c, d = self.cell, self.data
        rot = d.xmat[c.part_body].reshape(3, 3)  # columns: the part's axes in the world
        axis = d.xmat[c.tcp_body].reshape(3, 3)[:, 2]
        return rot.T @ (d.xpos[c.tcp_body] - d.xpos[c.part_body]), rot.T @ axis

    def level_reached(self) -> float:
        """kPa below atmosphere the generator reaches with the cup where it is (`seal.level_reached`)."""
        rel, axis = self._lip()
        return seal.level_reached(rel, axis, self.boxes, self.vacuum.sealed_level_kpa, self.vacuum.open_level_kpa)

    def lip_sealed(self) -> bool:
        """The cup's lip rests whole on a face of the part: square to it, within the lip's compliance, not over an edge
        or a hole; or the seal's weld holds the part where it sealed."""
        if self.weld.active:
            return True
        lip = seal.lip_on_face(*self._lip(), self.boxes)
        return lip is not None and lip.rests and lip.open_area == 0.0
