"""The part library: every part the cell handles, as data, the same for both engines and the page.

A part is a few solid boxes in the part's frame (origin at the centre of its bounding box, z up, standing on its
bottom face; a hole is where no box is), its mass and friction, where its marker is printed, and what only the judge
reads (`PartJudging`: the acceptable grasp region, the keep-out windows and the place pose). The learner, the expert
path, the task's targets and the page read `boxes`, `height`, `mass`, `friction` and `marker`, never `judge_only`
(`part_judge` is its one reader; `tests/test_parts.py` checks it).

Nothing here says where a part is gripped: a person teaches it (`TaskConfig.grasp`, from the marks); a part nobody
taught falls back to the centre prior (`task.centre_prior`). Adding a part: one `Part` in `PARTS` and its rows in the
tests that tabulate every part (docs/twin.md#the-part-library).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from mrguide.config import ConfigError


@dataclass(frozen=True)
class Box:
    """A solid box of a part (m, in the part's frame): its centre and half extents."""

    centre: tuple[float, float, float]
    half: tuple[float, float, float]

    @property
    def volume(self) -> float:
        """m³."""
        return 8.0 * self.half[0] * self.half[1] * self.half[2]


@dataclass(frozen=True)
class Rect:
    """An axis-aligned rectangle of x, y in the part's frame (m), seen from above."""

    low: tuple[float, float]
    high: tuple[float, float]

    def distance(self, xy: np.ndarray) -> float:
        """m from point `xy` to the rectangle (0 inside it)."""
        gap = np.maximum(np.maximum(np.asarray(self.low) - xy, xy - np.asarray(self.high)), 0.0)
        return float(np.hypot(*gap))


@dataclass(frozen=True)
class PartJudging:
    """What only the judge reads (`part_judge`): where a grasp is acceptable and where the part is to be placed."""

    #: where the cup's axis may meet the top (x, y in the part's frame): the union of these
    grasp: tuple[Rect, ...]
    #: windows on the top the cup's lip must not touch (a label, a fragile face)
    keep_out: tuple[Rect, ...] = ()
    #: m, where the part's origin belongs, from the goal (x, y in the base frame)
    place_offset: tuple[float, float] = (0.0, 0.0)
    place_yaw: float = 0.0  # rad, the part's yaw at its place
    #: the part looks the same turned by 2π / symmetry about z (1: it has one right yaw)
    symmetry: int = 1
    place_tolerance: float = 0.03  # m, of the part's origin in x, y
    yaw_tolerance: float = math.radians(10.0)  # rad, of the yaw; also of the tilt off upright


@dataclass(frozen=True)
class Part:
    """A part the cell picks and places."""

    name: str
    boxes: tuple[Box, ...]  # solid material, not overlapping
    mass: float  # kg
    friction: float  # lateral friction coefficient on the table and the lip
    #: centre of the marker's print on a top face (its normal +z, its edges along x and y), in the part's frame
    marker: tuple[float, float, float]
    judge_only: PartJudging

    @property
    def height(self) -> float:
        """m from the part's bottom to its top: its origin stands at half of it above the table."""
        low, high = self.bounds
        return high[2] - low[2]

    @property
    def bounds(self) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
        """m, the low and high corners of the part's bounding box in its frame."""
        low = np.min([np.subtract(b.centre, b.half) for b in self.boxes], axis=0)
        high = np.max([np.add(b.centre, b.half) for b in self.boxes], axis=0)
        return (tuple(float(v) for v in low), tuple(float(v) for v in high))  # type: ignore[return-value]

    def surface_height(self, xy: np.ndarray) -> float | None:
        """m, in the part's frame, of the highest top face at `xy` seen from above; None where no box is (a hole)."""
        tops = [
            b.centre[2] + b.half[2]
            for b in self.boxes
            if abs(xy[0] - b.centre[0]) <= b.half[0] and abs(xy[1] - b.centre[1]) <= b.half[1]
        ]
        return max(tops) if tops else None

    @property
    def volume(self) -> float:
        """m³ of material."""
        return sum(b.volume for b in self.boxes)

    @property
    def centre_of_mass(self) -> tuple[float, float, float]:
        """m, in the part's frame, of material of even density."""
        weights = np.array([b.volume for b in self.boxes])
        com = weights @ np.array([b.centre for b in self.boxes]) / self.volume
        return (float(com[0]), float(com[1]), float(com[2]))


#: kg/m³ of the block (0.20 kg in 5 cm): the other parts' masses are their volumes of the same material.
_DENSITY = 1600.0

PARTS: dict[str, Part] = {
    p.name: p
    for p in (
        # The 5 cm cube every figure so far was measured with (its mass and friction: the training twin's).
        Part(
            "block",
            (Box((0.0, 0.0, 0.0), (0.025, 0.025, 0.025)),),
            mass=0.20,
            friction=0.8,
            marker=(0.0, 0.0, 0.025),
            judge_only=PartJudging(grasp=(Rect((-0.005, -0.005), (0.005, 0.005)),), symmetry=4),
        ),
        # A 14 cm square plate, 1 cm thick, with a 3 cm square hole in its middle: four boxes framing the hole. The
        # cup seals on the frame only, 3.5-5 cm from the centre along x or y.
        Part(
            "hole_plate",
            (
                Box((0.0, -0.0425, 0.0), (0.07, 0.0275, 0.005)),
                Box((0.0, 0.0425, 0.0), (0.07, 0.0275, 0.005)),
                Box((-0.0425, 0.0, 0.0), (0.0275, 0.015, 0.005)),
                Box((0.0425, 0.0, 0.0), (0.0275, 0.015, 0.005)),
            ),
            mass=0.30,  # 187 cm³
            friction=0.8,
            marker=(0.0, -0.0425, 0.005),
            judge_only=PartJudging(
                grasp=(
                    Rect((-0.05, -0.05), (0.05, -0.035)),
                    Rect((-0.05, 0.035), (0.05, 0.05)),
                    Rect((-0.05, -0.05), (-0.035, 0.05)),
                    Rect((0.035, -0.05), (0.05, 0.05)),
                ),
                symmetry=4,
            ),
        ),
        # An L-bracket, 10 cm long and 6 cm wide: a 1 cm base and a 1 cm wall standing 6 cm at its -x end. The wall's
        # top is too narrow for the lip; the cup seals on the base, clear of the wall, its axis 2-7 cm from the wall's inside.
        Part(
            "l_bracket",
            (
                Box((0.0, 0.0, -0.025), (0.05, 0.03, 0.005)),
                Box((-0.045, 0.0, 0.005), (0.005, 0.03, 0.025)),
            ),
            mass=0.14,  # 90 cm³
            friction=0.8,
            marker=(0.005, 0.0, -0.02),
            judge_only=PartJudging(grasp=(Rect((-0.019, -0.01), (0.03, 0.01)),), symmetry=1),
        ),
        # A 13 × 6 × 4 cm block with a 2 cm label across the middle of its top that the lip must not touch: the cup
        # seals with its axis up to 4.5 cm off the centre along x, but is acceptable only 3-4.5 cm off it, clear of the
        # label.
        Part(
            "keepout_block",
            (Box((0.0, 0.0, 0.0), (0.065, 0.03, 0.02)),),
            mass=0.50,  # 312 cm³
            friction=0.8,
            marker=(0.037, 0.0, 0.02),
            judge_only=PartJudging(
                grasp=(Rect((-0.045, -0.01), (0.045, 0.01)),),
                keep_out=(Rect((-0.01, -0.03), (0.01, 0.03)),),
                symmetry=2,
            ),
        ),
    )
}


def part_drawing(part: Part) -> dict[str, Any]:
    """What the annotation page draws of `part` (JSON): its name, height and boxes; nothing the judge reads."""
    boxes = [{"centre": list(b.centre), "half": list(b.half)} for b in part.boxes]
    return {"name": part.name, "height": part.height, "boxes": boxes}


def part_named(name: str, where: str = "task.part") -> Part:
    """The library's part `name`; ConfigError naming `where` and the parts there are otherwise."""
    try:
        return PARTS[name]
    except KeyError:
        raise ConfigError(f"{where} = {name!r}: expected one of {', '.join(PARTS)}") from None
