"""The cell's hardware, the same in every engine and drawing of it: the table, the suction cup and its mounting
(robot base frame, m)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from mrguide.config import Range, check_ranges

#: Radius of the suction cup's lip.
CUP_RADIUS = 0.02
#: The table: a box whose top face is at z = 0.
TABLE_CENTER = (0.45, 0.10, -0.02)
TABLE_HALF_EXTENTS = (0.55, 0.60, 0.02)


@dataclass(frozen=True)
class CupConfig:
    """The suction cup's mounting: rigid, or on a spring level-compensator that absorbs height error."""

    #: m the cup may retract towards the flange; 0 = rigid
    stroke: Annotated[float, Range(0.0, 0.05, " m")] = 0.012
    spring_rate: Annotated[float, Range(1.0, 1e6, " N/m")] = 1000.0
    preload: Annotated[float, Range(0.0, 1000.0, " N")] = 5.0  # N pushing the cup out at full extension

    def __post_init__(self) -> None:
        check_ranges(self, "twin.cup")
