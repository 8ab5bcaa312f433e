"""The MuJoCo cell's physical parameters ([plant.mujoco] of a cell config), each with where its value comes from.

None is fitted to a policy or copied from the PyBullet twin's tuning: contact, friction and solver settings are
MuJoCo's own defaults; the rest are the part's material and assumptions named as such. The cup and its seal are the
cell's hardware (`cell_layout`, `mrguide.seal`), the same as the twin's.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from mrguide.config import Range, check_ranges


@dataclass(frozen=True)
class MujocoCellConfig:
    """Physics of the MuJoCo cell."""

    #: Physics step (s). MuJoCo's default is 2 ms; 1 ms divides the 4 ms SYNC period into 4 steps.
    timestep: Annotated[float, Range(1e-5, 0.01, " s")] = 0.001
    #: Bandwidth of each drive's position loop (Hz), a second-order servo with velocity feed-forward on the
    #: link inertia at home. Assumed: the order of an industrial servo's position loop (10-30 Hz).
    servo_bandwidth_hz: Annotated[float, Range(0.5, 200.0, " Hz")] = 15.0
    servo_damping_ratio: Annotated[float, Range(0.1, 5.0)] = 1.0
    #: The part's mass in this cell; None: the part library's (`mrguide.parts`). The cell's config sets the block's
    #: as a solid 5 cm cube of ABS (density 1.04 g/cm³ → 0.13 kg).
    part_mass: Annotated[float | None, Range(1e-3, 10.0, " kg")] = None

    def __post_init__(self) -> None:
        check_ranges(self, "plant.mujoco")
