"""The judge of a part's pick and place (`mrguide.part_judge`): the grasp inside the part's hidden region and clear of
its keep-out window, the part at its place pose up to its symmetry."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mrguide.part_judge import grasp_acceptable, judge
from mrguide.parts import PARTS

GOAL = np.array([0.5, 0.2, 0.025])


def _yawed(yaw: float) -> np.ndarray:
    """Quaternion x, y, z, w of `yaw` about z."""
    return np.array([0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)])


@pytest.mark.parametrize(
    ("part", "grasp", "acceptable"),
    [
        ("block", (0.0, 0.0), True),
        ("block", (0.005, -0.005), True),  # the region's corner: the lip just on the face
        ("block", (0.006, 0.0), False),
        ("hole_plate", (0.0, 0.0), False),  # over the hole
        ("hole_plate", (0.0, 0.04), True),
        ("hole_plate", (0.04, -0.045), True),
        ("hole_plate", (0.0, 0.03), False),  # the lip over the hole's edge
        ("l_bracket", (0.0, 0.0), True),
        ("l_bracket", (-0.03, 0.0), False),  # the inside corner
        ("keepout_block", (0.035, 0.0), True),
        ("keepout_block", (-0.04, 0.005), True),
        ("keepout_block", (0.0, 0.0), False),  # on the window
        ("keepout_block", (0.025, 0.0), False),  # sealed, but the lip touches the window
    ],
)
def test_a_grasp_is_acceptable_inside_the_hidden_region_clear_of_keep_out(part, grasp, acceptable):
    assert grasp_acceptable(PARTS[part], np.array([*grasp, 0.0])) == acceptable


def test_a_part_is_placed_within_the_tolerance_of_its_place():
    block = PARTS["block"]
    at = GOAL + [0.02, -0.02, 0.0]
    verdict = judge(block, np.zeros(3), at, _yawed(0.0), GOAL)
    assert (
        verdict.grasp_acceptable and verdict.placed and verdict.position_error == pytest.approx(math.hypot(0.02, 0.02))
    )
    assert not judge(block, np.zeros(3), GOAL + [0.031, 0.0, 0.0], _yawed(0.0), GOAL).placed


def test_yaw_counts_up_to_the_parts_symmetry():
    block, bracket, bar = PARTS["block"], PARTS["l_bracket"], PARTS["keepout_block"]
    assert judge(block, np.zeros(3), GOAL, _yawed(math.pi / 2 + 0.05), GOAL).placed  # a square: every quarter turn
    assert not judge(block, np.zeros(3), GOAL, _yawed(math.pi / 4), GOAL).placed
    assert judge(bar, np.zeros(3), GOAL, _yawed(math.pi - 0.1), GOAL).placed  # a bar: either end
    assert not judge(bar, np.zeros(3), GOAL, _yawed(math.pi / 2), GOAL).placed
    verdict = judge(bracket, np.zeros(3), GOAL, _yawed(math.pi), GOAL)  # an L: one yaw only
    assert not verdict.placed and verdict.yaw_error == pytest.approx(math.pi)
    assert judge(bracket, np.zeros(3), GOAL, _yawed(-0.1), GOAL).yaw_error == pytest.approx(0.1)


def test_a_part_on_its_side_is_not_placed():
    on_side = np.array([math.sin(math.pi / 4), 0.0, 0.0, math.cos(math.pi / 4)])  # 90° about x
    verdict = judge(PARTS["block"], np.zeros(3), GOAL, on_side, GOAL)
    assert not verdict.placed and verdict.tilt == pytest.approx(math.pi / 2)


def test_the_place_pose_is_the_goal_moved_by_the_offset_and_turned_by_the_yaw():
    hidden = dataclasses.replace(PARTS["l_bracket"].judge_only, place_offset=(0.05, 0.0), place_yaw=math.pi / 2)
    part = dataclasses.replace(PARTS["l_bracket"], judge_only=hidden)
    assert judge(part, np.zeros(3), GOAL + [0.05, 0.0, 0.0], _yawed(math.pi / 2), GOAL).placed
    assert not judge(part, np.zeros(3), GOAL, _yawed(math.pi / 2), GOAL).placed
    assert not judge(part, np.zeros(3), GOAL + [0.05, 0.0, 0.0], _yawed(0.0), GOAL).placed
