"""The MuJoCo cup holds a sealed part by a weld (`mujoco_cell.seal_weld`): no drift across the lip as the base turns
(MuJoCo's contacts alone let the part creep: `tools/slip_probe.py`), and the seal still lets go where its load passes
what the vacuum holds, or when the vacuum is switched off."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.motion.kinematics import Kinematics
from mrguide.motion.trajectory import point_to_point
from mrguide.mujoco_cell.config import MujocoCellConfig
from mrguide.mujoco_cell.plant import MujocoPlant
from mrguide.robot import load_robot

PART = np.array([0.50, -0.10, 0.025])
PERIOD = 0.004


class Cell:
    """The MuJoCo cell stepped directly, one control period at a time (no bus)."""

    def __init__(self, part_mass: float | None = None):
        self.spec = load_robot()
        cfg = MujocoCellConfig() if part_mass is None else MujocoCellConfig(part_mass=part_mass)
        self.kin, self.plant = Kinematics(self.spec), MujocoPlant(self.spec, cfg)
        self.plant.place_objects(PART, PART + [0.0, 0.2, 0.0])

    def move_joints(self, q_to: np.ndarray, hold: int = 50) -> None:
        for q in [*point_to_point(self.spec, self.plant.joint_positions(), q_to, PERIOD), *[q_to] * hold]:
            self.plant.set_joint_targets(q)
            self.plant.step(PERIOD)

    def move_to(self, target: np.ndarray, hold: int = 50) -> None:
        self.move_joints(self.kin.ik(target, self.plant.joint_positions()), hold)

    def pick(self) -> None:
        """Press on the part's top, vacuum on, wait for the level, lift 12.5 cm."""
        self.move_to(PART + [0.0, 0.0, 0.08])
        self.move_to(PART + [0.0, 0.0, 0.025])
        self.plant.set_vacuum(True, False)
        self.move_to(PART + [0.0, 0.0, 0.025], hold=100)
        self.move_to(PART + [0.0, 0.0, 0.15])

    def part_in_cup_frame(self) -> np.ndarray:
        d, c = self.plant.data, self.plant.cell
        return d.xmat[c.tcp_body].reshape(3, 3).T @ (d.xpos[c.part_body] - d.xpos[c.tcp_body])


@pytest.fixture(scope="module")
def held() -> Cell:
    cell = Cell()
    cell.pick()
    return cell


def test_a_sealed_part_is_held_where_it_sealed_through_a_turn_of_the_base(held):
    assert held.plant.weld.active and held.plant.part_present() and held.plant.lip_sealed()
    start = held.part_in_cup_frame()
    held.move_joints(held.plant.joint_positions() + 0.8 * np.eye(held.spec.dof)[0], hold=20)
    assert np.linalg.norm(held.part_in_cup_frame() - start) < 5e-5  # 0.75 mm with the contacts alone
    force, _ = held.plant.weld.load()
    weight = held.plant.model.body_mass[held.plant.cell.part_body] * 9.81
    assert force[2] == pytest.approx(weight, rel=0.05)  # at rest the weld carries the part's weight


def test_the_vacuum_switched_off_lets_the_part_go():
    cell = Cell()
    cell.pick()
    assert cell.plant.weld.active
    cell.plant.set_vacuum(False, True)
    cell.move_joints(cell.plant.joint_positions(), hold=100)
    assert not cell.plant.weld.active
    assert cell.plant.object_position()[2] < 0.03  # fallen to the table


def test_a_seal_whose_level_no_longer_holds_the_part_lets_it_fall():
    """A 2 kg part (19.6 N) held at the sealed level (75 kPa: 94 N); a leak takes the level to 15 kPa (18.8 N)."""
    cell = Cell(part_mass=2.0)
    cell.pick()
    assert cell.plant.weld.active and cell.plant.object_position()[2] > 0.1
    cell.plant.set_vacuum_leak(0.8)
    cell.move_joints(cell.plant.joint_positions(), hold=250)
    assert not cell.plant.weld.active
    assert cell.plant.object_position()[2] < 0.03
