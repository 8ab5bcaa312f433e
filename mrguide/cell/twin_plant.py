"""The twin as the plant behind the simulated CANopen drives and vacuum generator (dry runs, sim-to-real).

`TwinPlant` implements the driver layer's `Plant`: the simulated cobot calls it once per SYNC from its
CAN thread; each call steps PyBullet by one control period with the received CSP targets. PyBullet is not
thread-safe, so every access (also the exact object pose read by the deploy runtime) takes one lock.
"""

from __future__ import annotations

import threading

import numpy as np

from mrguide.plant import CellPlant, CellView
from mrguide.pose_source import ObjectPoseSource
from mrguide.twin.scene import Scene


class TwinPlant(CellPlant):
    """A `Scene` driven through the `Plant` interface."""

    def __init__(self, scene: Scene):
        self.scene = scene
        self.lock = threading.Lock()
        self._target = scene.joint_positions(noisy=False)
        self._prev_target = self._target.copy()

    @property
    def dof(self) -> int:
        return self.scene.spec.dof

    def step(self, dt: float) -> None:
        period = self.scene.cfg.control_period
        if abs(dt - period) > 1e-9:
            raise ValueError(f"twin plant steps {period} s per SYNC, the bus runs {dt} s")
        with self.lock:
            dq = (self._target - self._prev_target) / dt
            self._prev_target = self._target.copy()
            self.scene.command(self._target, dq)
            self.scene.step()

    def set_joint_targets(self, q: np.ndarray) -> None:
        self._target = np.asarray(q, dtype=float).copy()

    def joint_positions(self) -> np.ndarray:
        with self.lock:
            return self.scene.joint_positions()

    def joint_velocities(self) -> np.ndarray:
        with self.lock:
            return self.scene.joint_velocities()

    def set_vacuum(self, on: bool, blow_off: bool) -> None:
        with self.lock:
            self.scene.set_vacuum(bool(on) and not blow_off)

    def vacuum_level_kpa(self) -> float:
        """kPa below atmosphere (the scene reports gauge pressure, negative under vacuum)."""
        with self.lock:
            return max(0.0, -self.scene.vacuum_level())

    def part_present(self) -> bool:
        with self.lock:
            return self.scene.suction.state.attached

    def set_vacuum_leak(self, fraction: float) -> None:
        if not 0.0 <= fraction <= 1.0:
            raise ValueError(f"leak fraction must be in [0, 1], got {fraction}")
        with self.lock:
            self.scene.suction.leak = float(fraction)

    def place_objects(self, obj: np.ndarray, goal: np.ndarray) -> None:
        """New episode in the twin: object and goal placed, the arm left where the drives hold it."""
        with self.lock:
            self.scene.place_objects(obj, goal)

    @property
    def goal(self) -> np.ndarray:
        return self.scene.goal.copy()

    def object_position(self) -> np.ndarray:
        with self.lock:
            return self.scene.object_position()

    def view(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What a camera sees, read at one instant: object position, quaternion (x, y, z, w), true joints."""
        with self.lock:
            pos, orn = self.scene.object_pose()
            return pos, orn, self.scene.joint_positions(noisy=False)


class TwinObjectPose(ObjectPoseSource):
    """Exact object position from the environment model (sim-to-real conditions 1 and 2)."""

    def __init__(self, plant: CellView):
        self.plant = plant

    def object_position(self) -> np.ndarray:
        return self.plant.object_position()

    def pose_details(self) -> dict:
        """For the run log: the exact pose is the true one, of no age."""
        return {"true": self.plant.object_position(), "age_s": 0.0}
