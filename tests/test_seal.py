"""The seal model of `mrguide.seal`: the lip's open area past the face, the level its leak leaves, when the lip rests
on a face, and what the level holds."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from mrguide import seal
from mrguide.cell_layout import CUP_RADIUS
from mrguide.parts import PARTS, Box

HALF = (0.025, 0.025)  # the 5 cm part's top face
SEALED, OPEN = 75.0, 8.0  # kPa, the drivers' simulated generator


def _grid_open_area(centre: tuple[float, float], half: tuple[float, float], n: int = 2001) -> float:
    g = np.linspace(-CUP_RADIUS, CUP_RADIUS, n)
    x, y = np.meshgrid(g, g)
    on_lip = x**2 + y**2 <= CUP_RADIUS**2
    on_face = (np.abs(x + centre[0]) <= half[0]) & (np.abs(y + centre[1]) <= half[1])
    return float((on_lip & ~on_face).sum()) * (g[1] - g[0]) ** 2


@pytest.mark.parametrize(
    "centre", [(0.006, 0.0), (-0.01, 0.008), (0.012, 0.012), (0.02, -0.015), (0.0, -0.03), (0.03, 0.03)]
)
def test_the_open_area_is_the_lip_disc_outside_the_face(centre):
    exact, counted = seal.open_area(centre, HALF), _grid_open_area(centre, HALF)
    assert exact == pytest.approx(counted, rel=0.02, abs=2e-7)


def test_a_lip_past_one_edge_opens_the_circular_segment_beyond_it():
    r = CUP_RADIUS
    for d in (1e-5, 1e-4, 5e-4, 2e-3):
        segment = r * r * math.acos((r - d) / r) - (r - d) * math.sqrt(2 * r * d - d * d)
        assert seal.open_area((HALF[0] - r + d, 0.0), HALF) == pytest.approx(segment, rel=1e-6)


def test_a_lip_whole_on_the_face_is_not_open_and_one_beside_it_all_open():
    assert seal.open_area((0.005, -0.005), HALF) == 0.0
    assert seal.open_area((0.1, 0.0), HALF) == pytest.approx(math.pi * CUP_RADIUS**2)


def test_the_leak_area_is_the_generators_free_flow_through_a_choked_orifice():
    # the textbook figure for air from the atmosphere: 0.0404 p / √T kg/(s m²) through a choked orifice
    density = 101325.0 / (287.0 * 293.0)
    choked_flow = 0.0404 * 101325.0 / math.sqrt(293.0) / density  # m³/s per m² at atmospheric density
    area = (0.5 / 3600.0) / (seal.DISCHARGE_COEFFICIENT * choked_flow)
    assert pytest.approx(area, rel=0.01) == seal.LEAK_AREA
    assert 1.0e-6 < seal.LEAK_AREA < 1.3e-6


def test_the_level_falls_linearly_with_the_open_area_to_the_open_cups():
    assert seal.leak_level(0.0, SEALED, OPEN) == SEALED
    assert seal.leak_level(0.25 * seal.LEAK_AREA, SEALED, OPEN) == pytest.approx(0.75 * SEALED)
    assert seal.leak_level(0.5 * seal.LEAK_AREA, SEALED, OPEN) == pytest.approx(0.5 * SEALED)
    assert seal.leak_level(seal.LEAK_AREA, SEALED, OPEN) == OPEN
    levels = [seal.leak_level(a, SEALED, OPEN) for a in np.linspace(0.0, 2.0 * seal.LEAK_AREA, 50)]
    assert all(b <= a for a, b in itertools.pairwise(levels))


def _share_past_the_edge(share: float) -> float:
    """The lip's centre (m, along x) at which `share` of the lip's circumference lies past the face's edge."""
    return HALF[0] - CUP_RADIUS * math.cos(math.pi * share)


def test_a_few_percent_of_the_lip_open_lose_most_of_the_vacuum():
    def level(share: float) -> float:
        return seal.leak_level(seal.open_area((_share_past_the_edge(share), 0.0), HALF), SEALED, OPEN)

    assert level(0.02) > 0.85 * SEALED  # 2 % of the circumference: a 0.04 mm overhang, 0.09 mm² open
    assert level(0.04) < 0.55 * SEALED  # 4 %: below the 35 kPa part threshold
    assert level(0.05) == OPEN  # 5 %: nothing left of the seal


def test_the_seal_ends_a_fraction_of_a_millimetre_past_the_geometric_limit():
    limit = HALF[0] - CUP_RADIUS
    rel, axis, block = np.array([limit, 0.0, HALF[0]]), np.array([0.0, 0.0, -1.0]), PARTS["block"].boxes
    assert seal.level_reached(rel, axis, block, SEALED, OPEN) == SEALED
    past = rel + [0.0003, 0.0, 0.0]
    assert seal.level_reached(past, axis, block, SEALED, OPEN) < 35.0


def test_the_lip_rests_within_its_compliance_square_to_the_face():
    block, centred = PARTS["block"].boxes, np.array([0.0, 0.0, 0.025])
    down = np.array([0.0, 0.0, -1.0])

    def rests(rel: np.ndarray, axis: np.ndarray) -> bool | None:
        lip = seal.lip_on_face(rel, axis, block)
        return None if lip is None else lip.rests

    assert rests(centred + [0, 0, 0.0009], down)
    assert rests(centred - [0, 0, 0.002], down)  # pressed into the face: compressed, still on it
    assert not rests(centred + [0, 0, 0.0011], down)
    tilt = math.radians(1.0)
    assert rests(centred, np.array([math.sin(tilt), 0.0, -math.cos(tilt)]))
    tilt = math.radians(2.0)
    assert not rests(centred, np.array([math.sin(tilt), 0.0, -math.cos(tilt)]))
    assert rests(centred, -down) is None  # pointing away from the part
    side = np.array([0.025, 0.0, 0.0])
    assert rests(side, np.array([-1.0, 0.0, 0.0]))  # any face of the box
    assert list(seal.face_normal(np.array([-1.0, 0.0, 0.0]))) == [1.0, 0.0, 0.0]


def test_the_level_holds_its_force_off_the_face_and_friction_along_it():
    force = seal.holding_force(35.0)
    assert force == pytest.approx(35e3 * math.pi * CUP_RADIUS**2)  # 44 N
    assert seal.holds(0.99 * force, 0.0, 35.0)
    assert not seal.holds(1.01 * force, 0.0, 35.0)
    weight = 0.2 * 9.81
    assert seal.holds(weight, seal.LIP_FRICTION * (force - weight) * 0.99, 35.0)
    assert not seal.holds(weight, seal.LIP_FRICTION * (force - weight) * 1.01, 35.0)
    assert seal.holds(-100.0, 60.0, 35.0)  # pressed onto the face: friction carries more
    assert not seal.holds(weight, 0.0, 0.0)


def _level_over(part: str, xy: tuple[float, float], height: float) -> float:
    """The level with the cup pointing down, its lip `height` above the part's origin at `xy` of its frame."""
    rel, down = np.array([*xy, height]), np.array([0.0, 0.0, -1.0])
    return seal.level_reached(rel, down, PARTS[part].boxes, SEALED, OPEN)


def test_faces_of_several_boxes_at_one_height_seal_as_one():
    two = (Box((-0.02, 0.0, 0.0), (0.02, 0.03, 0.01)), Box((0.02, 0.0, 0.0), (0.02, 0.03, 0.01)))
    lip = seal.lip_on_face(np.array([0.0, 0.0, 0.01]), np.array([0.0, 0.0, -1.0]), two)
    assert lip is not None and lip.rests and lip.open_area == 0.0  # across the seam
    lip = seal.lip_on_face(np.array([0.025, 0.0, 0.01]), np.array([0.0, 0.0, -1.0]), two)
    assert lip is not None and lip.open_area == pytest.approx(seal.open_area((0.025, 0.0), (0.04, 0.03)), rel=1e-9)


def test_the_plate_seals_on_its_frame_not_over_its_hole():
    top = 0.005
    assert _level_over("hole_plate", (0.0, 0.0), top) == OPEN  # the lip's disc over the hole
    assert _level_over("hole_plate", (0.0, -0.0425), top) == SEALED  # on the frame, across no edge
    assert _level_over("hole_plate", (0.0, -0.0351), top) == SEALED  # the lip 0.1 mm off the hole
    assert _level_over("hole_plate", (0.0, -0.0347), top) < 35.0  # 0.3 mm over it
    assert _level_over("hole_plate", (-0.035, -0.035), top) == SEALED  # across the seam of two boxes


def test_the_bracket_seals_on_its_base_clear_of_the_wall_and_never_on_the_wall():
    base, wall = -0.02, 0.03
    assert _level_over("l_bracket", (0.005, 0.0), base) == SEALED
    assert _level_over("l_bracket", (-0.0199, 0.0), base) == SEALED  # the lip 0.1 mm off the wall
    assert _level_over("l_bracket", (-0.0201, 0.0), base) == OPEN  # the wall rises through the lip's disc
    assert _level_over("l_bracket", (-0.045, 0.0), wall) == OPEN  # the wall's top: 1 cm wide
    assert _level_over("l_bracket", (-0.03, 0.0), wall) == OPEN  # over the inside corner, resting on the wall
