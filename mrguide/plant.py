"""The plant interface: the physical arm and vacuum gripper behind the simulated CANopen devices, and what a simulated
cell's plant shows the dry-run harness and its cameras (`CellView`, `FedCell`). A seam every layer shares: numpy only.

The simulated cobot steps its plant exactly once per SYNC, from its CAN receive thread: it reads the
joint state, passes the drives' position targets and the vacuum command, then calls `step(dt)` with the
SYNC period. A PyBullet twin implements this with one physics step per SYNC.

Units: joint positions in rad, velocities in rad/s (robot joint order); vacuum level in kPa *below
atmosphere* (0 = atmospheric pressure, positive = vacuum; e.g. 60 kPa below atmosphere = -60 kPa gauge).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Protocol

import numpy as np


class Plant(ABC):
    """One object owning arm + vacuum gripper, advanced one SYNC period at a time."""

    @property
    @abstractmethod
    def dof(self) -> int:
        """Number of joints."""

    @abstractmethod
    def step(self, dt: float) -> None:
        """Advance the plant by `dt` seconds (one SYNC period) under the last targets and vacuum command."""

    @abstractmethod
    def set_joint_targets(self, q: np.ndarray) -> None:
        """Position targets (rad) the drives' position loops track during the next step."""

    @abstractmethod
    def joint_positions(self) -> np.ndarray:
        """Measured joint positions (rad)."""

    @abstractmethod
    def joint_velocities(self) -> np.ndarray:
        """Measured joint velocities (rad/s)."""

    @abstractmethod
    def set_vacuum(self, on: bool, blow_off: bool) -> None:
        """Vacuum generator valves: suction on, and/or blow-off (release pulse)."""

    @abstractmethod
    def vacuum_level_kpa(self) -> float:
        """Vacuum level at the suction cup in kPa below atmosphere (>= 0)."""

    @abstractmethod
    def part_present(self) -> bool:
        """Whether a part is at the suction cup (in contact / held)."""

    @abstractmethod
    def set_vacuum_leak(self, fraction: float) -> None:
        """Fault injection: a leak in the vacuum line; 0 = tight, 1 = no vacuum can build at the cup."""


class CellPlant(Plant):
    """A plant that is a whole simulated cell: a part to pick and a goal to place it at (dry runs, the sim-to-real
    conditions and their judges), and a view for the cameras. The PyBullet twin's and the MuJoCo cell's plants are
    ones; an engine registers its builder with `cell.plants.register_plant`."""

    @abstractmethod
    def place_objects(self, obj: np.ndarray, goal: np.ndarray) -> None:
        """A new layout: the part at rest at `obj` (m), the goal at `goal`; the arm left where the drives hold it."""

    @abstractmethod
    def object_position(self) -> np.ndarray:
        """The part's centre (m, robot base frame), the cell's ground truth."""

    @abstractmethod
    def view(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What a camera sees, read at one instant: part position, quaternion (x, y, z, w), true joints."""


class CellView(Protocol):
    """What pose sources and cameras read of a simulated cell's plant, whatever its engine (`TwinPlant`, the MuJoCo
    cell's `MujocoPlant`)."""

    def object_position(self) -> np.ndarray: ...

    def view(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...


class FedCell(CellView, Protocol):
    """What a dry run reads of and does to its cell's plant, in its own process or in the cell's (`cell_process`)."""

    def place_objects(self, obj: np.ndarray, goal: np.ndarray) -> None: ...
