"""The cell's hardware, the same in every engine and drawing of it: the table, the suction cup and its mounting
(robot base frame, m)."""

from __future__ import annotations

from dataclasses import dataclass

from mrguide.config import check_number

#: Radius of the suction cup's lip.
CUP_RADIUS = 0.02
#: The table: a box whose top face is at z = 0.
TABLE_CENTER = (0.45, 0.10, -0.02)
TABLE_HALF_EXTENTS = (0.55, 0.60, 0.02)


@dataclass(frozen=True)
class CupConfig:
    """The suction cup's mounting: rigid, or on a spring level-compensator that absorbs height error."""

    stroke: float = 0.0  # m the cup may retract towards the flange; 0 = rigid (trained so far)
    spring_rate: float = 1000.0  # N/m
    preload: float = 5.0  # N pushing the cup out at full extension

    def __post_init__(self) -> None:
        check_number("twin.cup.stroke", self.stroke, 0.0, 0.05, " m")
        check_number("twin.cup.spring_rate", self.spring_rate, 1.0, 1e6, " N/m")
        check_number("twin.cup.preload", self.preload, 0.0, 1000.0, " N")
