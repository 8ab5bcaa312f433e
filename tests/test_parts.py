"""The part library (`mrguide.parts`): each part's data is sound, the block is the part every figure so far used,
`[task] part` picks one by name, and only the judge reads what is hidden from the learner."""

from __future__ import annotations

import ast
import itertools
from pathlib import Path

import numpy as np
import pytest

from mrguide import seal
from mrguide.config import ConfigError
from mrguide.parts import PARTS, Part
from mrguide.policies.train_config import RunConfig
from mrguide.task import TaskConfig

PACKAGE = Path(__file__).resolve().parents[1] / "mrguide"
SEALED, OPEN = 75.0, 8.0  # kPa
#: m, the printed marker's half width: a 4 cm marker with its 5 mm quiet zone (`calibration.detector.marker_size_m`)
PRINT_HALF = 0.025


def _top_under(part: Part, xy: np.ndarray) -> float:
    """z of the part's highest material at `xy` of its frame."""
    return max(
        b.centre[2] + b.half[2] for b in part.boxes if np.all(np.abs(xy - np.asarray(b.centre[:2])) <= b.half[:2])
    )


@pytest.mark.parametrize("part", PARTS.values(), ids=list(PARTS))
def test_each_part_is_solid_boxes_about_its_bounding_box_centre(part):
    lo = np.min([np.subtract(b.centre, b.half) for b in part.boxes], axis=0)
    hi = np.max([np.add(b.centre, b.half) for b in part.boxes], axis=0)
    np.testing.assert_allclose(lo + hi, 0.0, atol=1e-12)
    assert part.height == pytest.approx(hi[2] - lo[2])
    for a, b in itertools.combinations(part.boxes, 2):  # touching at most
        gap = np.abs(np.subtract(a.centre, b.centre)) - np.add(a.half, b.half)
        assert gap.max() >= -1e-12, (part.name, a, b)
    assert part.mass / part.volume == pytest.approx(PARTS["block"].mass / PARTS["block"].volume, rel=0.03)


@pytest.mark.parametrize("part", PARTS.values(), ids=list(PARTS))
def test_each_marker_lies_whole_on_a_top_face(part):
    marker = np.asarray(part.marker)
    corners = [marker[:2] + PRINT_HALF * np.array(s) for s in itertools.product((-1, 1), repeat=2)]
    assert all(_top_under(part, c) == pytest.approx(marker[2]) for c in [marker[:2], *corners]), part.name


@pytest.mark.parametrize("part", PARTS.values(), ids=list(PARTS))
def test_the_cup_seals_everywhere_in_each_acceptable_grasp_region(part):
    down = np.array([0.0, 0.0, -1.0])
    for region in part.judge_only.grasp:
        for xy in itertools.product(*zip(region.low, region.high)):
            rel = np.array([*xy, _top_under(part, np.asarray(xy))])
            assert seal.level_reached(rel, down, part.boxes, SEALED, OPEN) == SEALED, (part.name, xy)


def test_the_block_is_todays_part():
    block = PARTS["block"]
    assert [(b.centre, b.half) for b in block.boxes] == [((0.0, 0.0, 0.0), (0.025, 0.025, 0.025))]
    assert (block.mass, block.friction, block.marker, block.height) == (0.20, 0.8, (0.0, 0.0, 0.025), 0.05)
    assert TaskConfig().part == "block" and TaskConfig().object_height == 0.05


def test_an_unknown_part_is_refused_naming_the_parts_there_are():
    with pytest.raises(ConfigError, match=r"task\.part = 'plate': expected one of block, hole_plate, l_bracket"):
        TaskConfig(part="plate")
    with pytest.raises(ConfigError, match=r"task\.part = 'plate'"):
        RunConfig().with_overrides({"task.part": "plate"}, "--set")
    assert RunConfig().with_overrides({"task.part": "l_bracket"}, "--set").env.task.object_height == pytest.approx(0.06)


def _reads_of_judge(path: Path) -> list[int]:
    """Lines of `path` that read an attribute `judge_only` or import `part_judge` / `PartJudging`."""

    def reads(node: ast.AST) -> bool:
        if isinstance(node, ast.Attribute):
            return node.attr == "judge_only"
        if isinstance(node, ast.ImportFrom):
            names = [node.module or "", *(a.name for a in node.names)]
            return any("part_judge" in n or n == "PartJudging" for n in names)
        return False

    return [node.lineno for node in ast.walk(ast.parse(path.read_text())) if reads(node)]


def test_only_the_judge_reads_what_the_learner_must_not_see():
    """The judge reads the hidden record, and the evaluation that calls it; the simulated person asks the judge once
    where to grip (a person knows the part) and whether a grip may stand, and only the simulated annotator asks the
    simulated person."""
    readers = {str(p.relative_to(PACKAGE)): _reads_of_judge(p) for p in PACKAGE.rglob("*.py")}
    knowing = ("experiments/part_grasps.py", "part_judge.py", "simulated_person.py")
    assert {p: lines for p, lines in readers.items() if lines} == {k: _reads_of_judge(PACKAGE / k) for k in knowing}
    assert _reads_of_judge(PACKAGE / "part_judge.py")  # the judge does read it: the scan sees a reader
    asking = [str(p.relative_to(PACKAGE)) for p in PACKAGE.rglob("*.py") if "simulated_person import" in p.read_text()]
    assert asking == ["policies/experts.py"]
    web = PACKAGE / "annotation" / "web"
    assert not [p for p in web.glob("*.js") if "judge_only" in p.read_text() or "keep_out" in p.read_text()]


def test_a_person_lets_a_grip_on_the_keepout_block_stand_only_clear_of_its_label_with_room_to_spare():
    """The simulated person corrects a grip they see wrong: on the label, beside it, or too near the edge of the grip
    region for a policy's wobble; the grip they would teach themselves stands."""
    from mrguide.simulated_person import SPARE, accepts, person_grasp

    taught = person_grasp("keepout_block")
    assert taught is not None and accepts("keepout_block", taught)
    assert not accepts("keepout_block", (0.0, 0.0, 0.02))  # the label
    edge = 0.01 + 0.020  # m: the label's half width and the cup's lip radius: the lip touches the label
    assert accepts("keepout_block", (edge + SPARE, 0.0, 0.02))
    assert not accepts("keepout_block", (edge + 0.5 * SPARE, 0.0, 0.02))  # acceptable, but no room to spare
    assert not accepts("keepout_block", (0.04, 0.01, 0.02))  # at the grip region's side
