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


def intended_grasp(part: Part, pitch: float = 0.0025) -> np.ndarray | None:
    """Where a person who knows the part grips it (m, in the part's frame, on its top face there): None where the
    centre of its top is acceptable (the centre prior serves them), else the acceptable point of a `pitch` grid
    deepest inside its grasp regions and clear of its keep-out windows, the nearest to the centre among equals."""
    if grasp_acceptable(part, np.zeros(2)) and part.surface_height(np.zeros(2)) is not None:
        return None
    best: tuple[float, float, np.ndarray] | None = None
    for region in part.judge_only.grasp:
        xs = np.arange(region.low[0], region.high[0] + 1e-9, pitch)
        ys = np.arange(region.low[1], region.high[1] + 1e-9, pitch)
        for xy in (np.array([x, y]) for x in xs for y in ys):
            if not grasp_acceptable(part, xy) or part.surface_height(xy) is None:
                continue
            depth = min(xy[0] - region.low[0], region.high[0] - xy[0], xy[1] - region.low[1], region.high[1] - xy[1])
            clear = min((w.distance(xy) - CUP_RADIUS for w in part.judge_only.keep_out), default=np.inf)
            key = (-round(min(depth, clear), 6), float(np.hypot(*xy)), xy)
            if best is None or key[:2] < best[:2]:
                best = key
    if best is None:
        raise ValueError(f"{part.name}: no acceptable grasp on a {pitch} m grid")
    xy = np.round(best[2], 6)
    return np.array([xy[0], xy[1], part.surface_height(xy)])


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
