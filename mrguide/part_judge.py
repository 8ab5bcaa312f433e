"""The judge of a part's pick and place: whether the grasp was where the part may be gripped and the part ended at its
place pose. The one reader of a part's hidden `judge_only` record (`mrguide.parts.PartJudging`); evaluation calls it, the
learner's path never does.

A grasp is acceptable where the cup's axis met the part inside one of the part's grasp regions, its lip (radius
`cell_layout.CUP_RADIUS`) clear of every keep-out window. A part is placed when its origin lies within the place
tolerance of the goal plus the place offset (x, y), it stands upright and its yaw is the place yaw, up to its
symmetry, within the yaw tolerance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mrguide.cell_layout import CUP_RADIUS
from mrguide.parts import Part


@dataclass(frozen=True)
class Verdict:
    """The judge's reading of one pick and place."""

    grasp_acceptable: bool
    placed: bool
    position_error: float  # m, the part's origin from its place, x and y
    yaw_error: float  # rad, from the place yaw, up to the part's symmetry
    tilt: float  # rad, of the part's z axis off vertical


def grasp_acceptable(part: Part, grasp: np.ndarray) -> bool:
    """Whether the cup's axis met the part's top at `grasp` (x, y, … in the part's frame) inside a grasp region with
    its lip clear of every keep-out window."""
    xy = np.asarray(grasp, dtype=float)[:2]
    inside = any(region.distance(xy) == 0.0 for region in part.judge_only.grasp)
    return inside and all(window.distance(xy) >= CUP_RADIUS for window in part.judge_only.keep_out)


def _yaw_and_tilt(quaternion: np.ndarray) -> tuple[float, float]:
    """The yaw (rad, of the x axis about z) and the tilt (rad, of the z axis off vertical) of quaternion x, y, z, w."""
    x, y, z, w = np.asarray(quaternion, dtype=float) / np.linalg.norm(quaternion)
    yaw = math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))
    return yaw, math.acos(min(1.0, max(-1.0, 1.0 - 2.0 * (x * x + y * y))))


def judge(part: Part, grasp: np.ndarray, position: np.ndarray, quaternion: np.ndarray, goal: np.ndarray) -> Verdict:
    """The verdict on a part gripped at `grasp` (part frame) and left at `position` (its origin, m) with `quaternion`
    (x, y, z, w), base frame, for the task's `goal` (m, base frame)."""
    j = part.judge_only
    place = np.asarray(goal, dtype=float)[:2] + j.place_offset
    position_error = float(np.linalg.norm(np.asarray(position, dtype=float)[:2] - place))
    yaw, tilt = _yaw_and_tilt(quaternion)
    period = 2.0 * math.pi / j.symmetry
    yaw_error = abs((yaw - j.place_yaw + 0.5 * period) % period - 0.5 * period)
    placed = position_error <= j.place_tolerance and yaw_error <= j.yaw_tolerance and tilt <= j.yaw_tolerance
    return Verdict(grasp_acceptable(part, grasp), placed, position_error, yaw_error, tilt)
