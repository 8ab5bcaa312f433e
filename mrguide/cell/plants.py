"""The engines a simulated cell can run on ([plant] engine) and how each builds the plant behind the simulated drives:
the PyBullet twin's scene with reality-gap parameters, or the MuJoCo cell. A new engine is one `register_plant` call."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import TYPE_CHECKING

from mrguide.cell.config import PLANT_ENGINES, CellConfig
from mrguide.cell.twin_plant import TwinPlant
from mrguide.drivers.config import CobotBusConfig
from mrguide.parts import part_named
from mrguide.plant import CellPlant
from mrguide.registries import register
from mrguide.robot import RobotSpec
from mrguide.twin.config import TwinConfig
from mrguide.twin.scene import Scene

if TYPE_CHECKING:
    from mrguide.mujoco_cell.plant import MujocoPlant


def _pybullet_plant(cell: CellConfig, twin_cfg: TwinConfig, spec: RobotSpec, seed: int) -> tuple[TwinPlant, Scene]:
    scene = Scene(spec, twin_cfg, part_named(cell.task.part), seed=seed)
    return TwinPlant(scene), scene


def _mujoco_plant(cell: CellConfig, twin_cfg: TwinConfig, spec: RobotSpec, seed: int) -> tuple[MujocoPlant, None]:
    from mrguide.mujoco_cell.plant import MujocoPlant  # the `mujoco` extra: only for a cell that asks for it

    return MujocoPlant(spec, cell.plant.mujoco, part_named(cell.task.part), cup=twin_cfg.cup), None


#: (env config, twin config, arm, seed) → the plant behind the simulated drives, and the twin's scene if it has one.
PlantBuilder = Callable[[CellConfig, TwinConfig, RobotSpec, int], tuple[CellPlant, Scene | None]]
#: How each engine of [plant] engine builds its plant (`register_plant`).
PLANT_BUILDERS: dict[str, PlantBuilder] = {}


def register_plant(engine: str, builder: PlantBuilder) -> None:
    """Make `[plant] engine = ENGINE` a cell's engine, built by `builder`; ValueError if the name is taken. The plant
    contract tests (`tests/cell/test_plant_contract.py`) run on every registered engine."""
    register(PLANT_BUILDERS, engine, builder, "plant engine", PLANT_ENGINES)


register_plant("pybullet", _pybullet_plant)
register_plant("mujoco", _mujoco_plant)


def build_plant(
    cell: CellConfig, bus_cfg: CobotBusConfig, spec: RobotSpec, seed: int
) -> tuple[CellPlant, Scene | None]:
    """The plant of the cell's [plant] engine, stepping one control period of `bus_cfg` per SYNC, no GUI."""
    twin_cfg = replace(cell.twin, control_period=bus_cfg.timing.control_period, gui=False)
    return PLANT_BUILDERS[cell.plant.engine](cell, twin_cfg, spec, seed)
