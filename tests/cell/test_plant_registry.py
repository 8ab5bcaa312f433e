"""A plant engine is registered where it is defined: a new one is a cell's engine without any edit of the config or
the dry run."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.cell import dry_run, plants
from mrguide.cell.config import PLANT_ENGINES, CellConfig, PlantConfig
from mrguide.config import ConfigError
from mrguide.drivers.mock import FirstOrderPlant
from mrguide.plant import CellPlant


class ToyCell(FirstOrderPlant, CellPlant):
    """The first-order plant as a whole cell: the part stays where it was put."""

    def place_objects(self, obj: np.ndarray, goal: np.ndarray) -> None:
        self.part, self.goal = np.array(obj, dtype=float), np.array(goal, dtype=float)

    def object_position(self) -> np.ndarray:
        return self.part.copy()

    def view(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return self.part.copy(), np.array([0.0, 0.0, 0.0, 1.0]), self.joint_positions()


def _toy(env_cfg, twin_cfg, spec, seed):
    return ToyCell(np.array(spec.q_home)), None


@pytest.fixture
def toy_engine():
    plants.register_plant("toy-first-order", _toy)
    yield "toy-first-order"
    del plants.PLANT_BUILDERS["toy-first-order"]
    PLANT_ENGINES.remove("toy-first-order")


def test_a_registered_engine_is_a_cells_engine_and_its_plant_plays_the_cell(toy_engine, make_config, robot):
    env_cfg = CellConfig(plant=PlantConfig(engine=toy_engine))
    with dry_run.simulated_cell(env_cfg, make_config()) as cell:
        assert isinstance(cell.plant, ToyCell) and cell.scene is None
        cell.plant.place_objects(np.array([0.5, -0.1, 0.025]), np.array([0.45, 0.2, 0.025]))
        assert np.allclose(cell.plant.object_position(), [0.5, -0.1, 0.025])
        assert np.allclose(cell.cobot.joint_state().positions, robot.q_home, atol=1e-3)  # enabled, holding home


def test_an_engine_nobody_registered_is_refused_and_a_name_is_registered_once():
    with pytest.raises(ConfigError, match=r"plant\.engine = 'toy-first-order'"):
        PlantConfig(engine="toy-first-order")
    with pytest.raises(ValueError, match="registered already"):
        plants.register_plant("mujoco", _toy)
