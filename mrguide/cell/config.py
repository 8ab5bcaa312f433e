"""A simulated cell's configuration: the twin of the cell that plays the robot ([robot], [twin], [task]) and the engine
it runs on ([plant]). Training reads the first three only (`EnvConfig`); [plant] belongs to the cell."""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

from mrguide.config import ConfigError, ConfigFile, replace_path
from mrguide.mujoco_cell.config import MujocoCellConfig
from mrguide.robot import RobotConfig
from mrguide.task import TaskConfig
from mrguide.twin.config import TwinConfig
from mrguide.twin.env import EnvConfig

#: The physics engines a simulated cell can run on ([plant] engine): the two shipped ones, and any a module registered
#: with `cell.plants.register_plant` (which builds each).
PLANT_ENGINES: list[str] = ["pybullet", "mujoco"]


@dataclass(frozen=True)
class PlantConfig:
    """[plant] of a cell config: the engine that plays the robot behind the simulated drives in dry runs and the
    sim-to-real conditions (the twin trains in PyBullet whatever this says), and the MuJoCo cell's physics."""

    engine: str = "pybullet"
    mujoco: MujocoCellConfig = field(default_factory=MujocoCellConfig)

    def __post_init__(self) -> None:
        if self.engine not in PLANT_ENGINES:
            raise ConfigError(f"plant.engine = {self.engine!r}: expected one of {', '.join(PLANT_ENGINES)}")


@dataclass(frozen=True)
class CellConfig:
    """A simulated cell: the env it models (robot, twin with its reality gap, task) and its engine ([plant])."""

    env: EnvConfig = field(default_factory=EnvConfig)
    plant: PlantConfig = field(default_factory=PlantConfig)

    @classmethod
    def load(cls, path: str | Path | None) -> CellConfig:
        """[robot], [twin], [task] and [plant] of `path`, the file parsed once."""
        return cls.from_file(ConfigFile.read(path))

    @classmethod
    def from_file(cls, file: ConfigFile) -> CellConfig:
        return cls(EnvConfig.from_file(file), file.section(PlantConfig, "plant"))

    @property
    def robot(self) -> RobotConfig:
        return self.env.robot

    @property
    def twin(self) -> TwinConfig:
        return self.env.twin

    @property
    def task(self) -> TaskConfig:
        return self.env.task

    def with_value(self, key: str, value: object, where: str) -> CellConfig:
        """This cell with dotted `key` ("plant.engine", "twin.reality_gap.object_mass", ...) set to `value`, checked as
        a value in its file would be (ConfigError naming `where`)."""
        if key.startswith("plant."):
            return replace(self, plant=replace_path(self.plant, key.removeprefix("plant."), value, where))
        return replace(self, env=replace_path(self.env, key, value, where))

    def with_twin(self, twin: TwinConfig) -> CellConfig:
        """This cell with another [twin] (a reality-gap sweep, a cup's stroke)."""
        return replace(self, env=replace(self.env, twin=twin))
