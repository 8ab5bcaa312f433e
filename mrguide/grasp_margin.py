"""Where on a part a grasp has room: how far the cup's lip could move before some of it leaves the face it rests on,
and the point nearest a taught grasp that leaves a seal the room it needs.

A cell program knows its part's model (`mrguide.parts`: the boxes; never what only the judge reads) and its cup's
lip (`cell_layout.CUP_RADIUS`). A person's taught grasp carries their errors: on the hole plate's 15 mm band of frame a
point taught 2 mm from the hole's edge seals in one demonstration and misses in the next, when the part is seen a few
millimetres off. So the cell keeps the person's point where it has `SEAL_MARGIN` of room, and otherwise moves it the
least it must, never further than `within` of it (`steady_grasp`): within the person's intent, away from an edge.
The runtime reads its presses against the window a grasp leaves per axis (`seal_window`, `deploy.bias_estimate`).
numpy only: the robot PC runs it.
"""

from __future__ import annotations

import functools

import numpy as np

from mrguide.cell_layout import CUP_RADIUS
from mrguide.parts import Part, part_named

#: m: the room a seal needs: the perception's error of the part's pose (3 mm per look and 3 mm of calibration per
#: axis in the HMD model, configs/runs/person.toml) once over (ours).
SEAL_MARGIN = 0.005
_RESOLUTION = 0.0005  # m, of the map of the part's top the margins are measured on


@functools.cache
def _off_face(part: str, height: float, reach: float) -> np.ndarray:
    """The points (x, y) of a grid over part `part`'s bounding box widened by `reach` where no face at `height` is
    but next to one: the nearest point off the face to a point on it is one of these."""
    (lx, ly, _), (hx, hy, _) = part_named(part).bounds
    xs = np.arange(lx - reach, hx + reach + _RESOLUTION, _RESOLUTION)
    ys = np.arange(ly - reach, hy + reach + _RESOLUTION, _RESOLUTION)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    top = np.full(gx.shape, -np.inf)
    for b in part_named(part).boxes:
        inside = (np.abs(gx - b.centre[0]) <= b.half[0]) & (np.abs(gy - b.centre[1]) <= b.half[1])
        top = np.where(inside, np.maximum(top, b.centre[2] + b.half[2]), top)
    on = np.pad(np.abs(top - height) <= 1e-9, 1)
    beside = on[:-2, 1:-1] | on[2:, 1:-1] | on[1:-1, :-2] | on[1:-1, 2:]
    edge = ~on[1:-1, 1:-1] & beside
    return np.stack([gx[edge], gy[edge]], axis=1)


def seal_margins(part: Part, points: np.ndarray, radius: float = CUP_RADIUS) -> np.ndarray:
    """m, for each cup axis point (x, y in the part's frame): how far the lip (`radius`) could move from there in any
    direction before some of it leaves the face under the point (negative: it does already; -inf over no face)."""
    points = np.atleast_2d(np.asarray(points, dtype=float))
    heights = [part.surface_height(p) for p in points]
    out = np.full(len(points), -np.inf)
    for h in {z for z in heights if z is not None}:
        mine = [i for i, z in enumerate(heights) if z == h]
        edge = _off_face(part.name, h, radius + 0.01)
        gaps = np.linalg.norm(points[mine][:, None, :] - edge[None, :, :], axis=2).min(axis=1)
        out[mine] = gaps - radius
    return out


def steady_grasp(part: Part, xy: np.ndarray, within: float, need: float = SEAL_MARGIN) -> np.ndarray:
    """The point (x, y, part frame) nearest `xy`, at most `within` from it, where a seal has `need` of room; where no
    point there has, the one with the most room, the nearest among equals."""
    return np.array(_steady(part.name, *(round(float(v), 5) for v in np.asarray(xy)[:2]), within, need))


def seal_window(part: Part, xy: np.ndarray, reach: float = 0.03) -> tuple[float, float]:
    """m, per axis (x, y): how far the cup's axis may move from `xy` (part frame) along that axis, either way, with
    the lip still resting whole on the face (the nearer of the two ways; at most `reach`)."""
    steps = np.arange(0.0, reach + _RESOLUTION, _RESOLUTION)
    out = []
    for axis in (0, 1):
        ways = []
        for sign in (1.0, -1.0):
            points = np.tile(np.asarray(xy, dtype=float)[:2], (len(steps), 1))
            points[:, axis] += sign * steps
            off = np.nonzero(seal_margins(part, points) < 0)[0]
            ways.append(float(steps[off[0] - 1]) if len(off) and off[0] > 0 else 0.0 if len(off) else reach)
        out.append(min(ways))
    return (out[0], out[1])


@functools.lru_cache(maxsize=256)
def _steady(part_name: str, x: float, y: float, within: float, need: float) -> tuple[float, float]:
    part, xy = part_named(part_name), np.array([x, y])
    steps = np.arange(-within, within + _RESOLUTION, _RESOLUTION)
    cand = np.array([xy + [dx, dy] for dx in steps for dy in steps if np.hypot(dx, dy) <= within + 1e-12])
    margins, dist = seal_margins(part, cand), np.linalg.norm(cand - xy, axis=1)
    roomy = margins >= need
    pick = roomy if roomy.any() else margins >= margins.max() - 1e-9
    best = cand[pick][np.argmin(dist[pick])]
    return (float(best[0]), float(best[1]))
