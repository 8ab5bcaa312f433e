"""Configuration of the twin: timing, randomization regions, reality-gap parameters, camera."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

from mrguide.cell_layout import CupConfig
from mrguide.config import ConfigError, Range, check_ranges
from mrguide.part_perception import PerceptionConfig
from mrguide.twin.camera import CameraConfig


@dataclass(frozen=True)
class RealityGap:
    """Physical parameters that differ between the training twin and the 'real' cell.

    The defaults are the training twin's (ideal actuators, noise-free sensors). A second twin playing
    the real robot loads other values, e.g. from `configs/cells/real_cell.toml`.
    """

    #: the part's mass in this cell; None: the part library's (`mrguide.parts`; the block's 0.20 kg)
    object_mass: Annotated[float | None, Range(1e-3, 10.0, " kg")] = None
    #: the part's lateral friction coefficient in this cell; None: the part library's (the block's 0.8)
    object_friction: Annotated[float | None, Range(0.01, 2.0)] = None
    #: N: the cup lets go above this constraint force, whatever its vacuum holds (`mrguide.seal`: Δp · A off the face,
    #: friction along it): a cup weaker than that, as a worn lip is. The training twin's 1000 N is none (Δp · A is at
    #: most 127 N for the 2 cm lip at a perfect vacuum); a 'real' cell sets its own.
    suction_break_force: Annotated[float, Range(0.1, 1000.0, " N")] = 1000.0
    #: control periods between a setpoint and its application
    actuator_latency: Annotated[int, Range(0, 100, " control periods")] = 0
    #: first-order time constant of the joint servo on its setpoint
    actuator_lag: Annotated[float, Range(0.0, 1.0, " s")] = 0.0
    joint_noise: Annotated[float, Range(0.0, 0.1, " rad")] = 0.0  # std of the measured joint positions
    vacuum_noise: Annotated[float, Range(0.0, 50.0, " kPa")] = 0.0  # std of the vacuum-level reading

    def __post_init__(self) -> None:
        check_ranges(self, "reality_gap")


@dataclass(frozen=True)
class Region:
    """Axis-aligned xy rectangle on the table (m)."""

    low: tuple[float, float] = (0.40, -0.15)
    high: tuple[float, float] = (0.60, 0.00)

    def __post_init__(self) -> None:
        if not (self.high[0] >= self.low[0] and self.high[1] >= self.low[1]):
            raise ConfigError(f"region: high {self.high} must not be below low {self.low}")


@dataclass(frozen=True)
class VacuumConfig:
    """Vacuum generator model, gauge pressures in kPa (negative = below atmosphere). Where the cup seals and the level
    its lip's leak leaves are the cell's (`mrguide.seal`, the same in both engines)."""

    level_sealed: float = -65.0  # kPa with a part on the cup
    level_open: float = -8.0  # kPa with the vacuum on and no part (flow through the open cup)
    part_threshold: float = -35.0  # kPa; part-present when the level is below this
    time_constant: Annotated[float, Range(1e-4, 10.0, " s")] = 0.03  # first-order response of the level

    def __post_init__(self) -> None:
        if not self.level_sealed < self.part_threshold < self.level_open <= 0:
            raise ConfigError(
                f"twin.vacuum: need level_sealed < part_threshold < level_open <= 0 kPa, got "
                f"{self.level_sealed}, {self.part_threshold}, {self.level_open}"
            )
        check_ranges(self, "twin.vacuum")


@dataclass(frozen=True)
class TwinConfig:
    """The twin of the cell ([twin] in a TOML config)."""

    #: Ruckig/physics step (default 4 ms, as the bus SYNC period)
    control_period: Annotated[float, Range(5e-4, 0.1, " s")] = 0.004
    decision_period: Annotated[float, Range(1e-4, 10.0, " s")] = 0.1  # one policy decision is executed for this long
    object_region: Region = field(default_factory=Region)
    goal_region: Region = field(default_factory=lambda: Region((0.40, 0.12), (0.60, 0.30)))
    reality_gap: RealityGap = field(default_factory=RealityGap)
    vacuum: VacuumConfig = field(default_factory=VacuumConfig)
    cup: CupConfig = field(default_factory=CupConfig)
    perception: PerceptionConfig = field(default_factory=PerceptionConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    gui: bool = False

    def __post_init__(self) -> None:
        check_ranges(self, "twin")
        ratio = self.decision_period / self.control_period
        if self.decision_period <= 0 or abs(ratio - round(ratio)) > 1e-6:
            raise ConfigError(
                f"twin.decision_period ({self.decision_period}) must be a positive multiple of the "
                f"control period ({self.control_period})"
            )

    @property
    def cycles_per_decision(self) -> int:
        return round(self.decision_period / self.control_period)
