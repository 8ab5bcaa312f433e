"""The cup seals on the library's parts where its lip rests whole on material, in both engines alike: across the hole
plate's hole and its outer edge, and across the L-bracket's base to its edge; over the bracket's inside corner, where
the lip meets the wall's top, neither seals. Lowered as `test_seal_geometry` lowers it, along x through the part's
origin; both engines must change between seal and no seal within 1 mm of each geometric limit."""

from __future__ import annotations

from dataclasses import replace

import pytest

from mrguide.cell.config import CellConfig
from mrguide.cell.plants import PLANT_BUILDERS
from mrguide.motion.kinematics import Kinematics
from mrguide.parts import PARTS
from mrguide.robot import load_robot
from tests.twin.test_seal_geometry import PERIOD, Row, lower_cup

#: part → (its top face under the cup, m above its origin; mm the cup's axis is lowered at, along x; the limits, mm,
#: where the lip's disc meets the face's edges along x: a seal between each pair).
CASES = {
    # the frame beside the hole: material for 15 mm ≤ |x| ≤ 70 mm
    "hole_plate": (0.005, (25.0, 33.0, 34.5, 35.5, 37.0, 42.5, 48.0, 49.5, 50.5, 55.0), (15.0 + 20.0, 70.0 - 20.0)),
    # the base beside the wall: the wall's inside at x = -40 mm, the base's end at 50 mm (the cup cannot pass the wall)
    "l_bracket": (-0.02, (-19.5, -10.0, 0.0, 15.0, 27.0, 29.5, 30.5, 32.0, 35.0), (-40.0 + 20.0, 50.0 - 20.0)),
}


def _table(part: str, face: float, offsets: tuple[float, ...]) -> dict[str, list[Row]]:
    """engine → its rows for `part`, one per offset."""
    spec, base = load_robot(), CellConfig()
    env = replace(base.env, task=replace(base.env.task, part=part))
    cell = replace(base, env=env)
    kin, half = Kinematics(spec), 0.5 * PARTS[part].height
    twin_cfg = replace(cell.twin, control_period=PERIOD, gui=False)
    out = {}
    for engine in ("pybullet", "mujoco"):
        plant, scene = PLANT_BUILDERS[engine](cell, twin_cfg, spec, 0)
        try:
            out[engine] = [lower_cup(plant, spec, kin, 1e-3 * mm, half, face) for mm in offsets]
        finally:
            if scene is not None:
                scene.close()
    return out


def _format(offsets: tuple[float, ...], tables: dict[str, list[Row]]) -> str:
    lines = ["commanded mm | " + " | ".join(f"{e}: offset mm, seal, level kPa" for e in tables)]
    for i, mm in enumerate(offsets):
        cells = [
            f"{t[i].offset_mm:6.2f}, {'yes' if t[i].seal else 'no '}, {t[i].level_kpa:5.1f}" for t in tables.values()
        ]
        lines.append(f"{mm:6.1f} | " + " | ".join(cells))
    return "\n".join(lines)


def _edges(rows: list[Row]) -> tuple[float, float]:
    """Where the seal begins and ends along x: midway between the sealing rows' outermost and their open neighbours
    (the seal one unbroken run; an edge with no open row beyond it is the outermost sealing row)."""
    seals = [r.seal for r in rows]
    first, last = seals.index(True), len(seals) - 1 - seals[::-1].index(True)
    assert all(seals[first : last + 1]), f"seal and no seal interleave: {rows}"
    low = rows[first].offset_mm if first == 0 else 0.5 * (rows[first - 1].offset_mm + rows[first].offset_mm)
    high = rows[last].offset_mm if last == len(rows) - 1 else 0.5 * (rows[last].offset_mm + rows[last + 1].offset_mm)
    return low, high


@pytest.mark.parametrize("part", list(CASES))
def test_both_engines_seal_on_the_parts_material_up_to_its_edges_and_agree_there(part):
    face, offsets, limits = CASES[part]
    tables = _table(part, face, offsets)
    print(f"\n{part}\n{_format(offsets, tables)}")
    edges = {engine: _edges(rows) for engine, rows in tables.items()}
    for engine, (low, high) in edges.items():
        if offsets[0] < limits[0]:  # the table crosses the lower limit
            assert abs(low - limits[0]) <= 1.0, f"{engine} seals from {low:.2f} mm\n{_format(offsets, tables)}"
        assert abs(high - limits[1]) <= 1.0, f"{engine} seals to {high:.2f} mm\n{_format(offsets, tables)}"
    assert max(abs(a - b) for a, b in zip(*edges.values(), strict=True)) <= 1.0, edges


def test_over_the_brackets_inside_corner_neither_engine_seals():
    """The cup lowered at x = -30 mm onto the wall's top (10 mm wide): its lip spans the corner."""
    tables = _table("l_bracket", 0.03, (-30.0,))
    print(f"\nl_bracket, onto the wall\n{_format((-30.0,), tables)}")
    assert not any(rows[0].seal for rows in tables.values()), _format((-30.0,), tables)
