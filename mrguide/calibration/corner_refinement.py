"""Marker corners from straight-edge fits: sub-pixel edge points along each side, a line per side,
corners where neighbouring lines meet.

OpenCV's SUBPIX refinement (`cornerSubPix`) is made for chessboard saddle points; on the convex outer
corners of a marker it is pulled inwards by about 0.1-0.3 px, which at 1 m makes a 4 cm marker look a few
millimetres farther away than it is. Edge points are taken where the intensity profile across the edge
crosses the midpoint between its dark and light levels (unbiased for any symmetric blur), away from the
corners, and each side's line is fitted with outliers (occluders, noise) removed. With lens distortion
the edge points are undistorted first, so the lines are straight.
"""

from __future__ import annotations

import cv2
import numpy as np

from mrguide.calibration.camera_model import CameraModel

_MIN_SIDE_PX = 12.0  # shorter sides are left as they are
_MIN_CONTRAST = 20.0  # grey levels between the dark and light side of an edge sample
_MIN_SAMPLES = 5  # edge samples a side needs for its line
_STEP_PX = 0.25  # sampling step across the edge


def _edge_points(gray: np.ndarray, a: np.ndarray, b: np.ndarray, half_cell: float) -> np.ndarray:
    """Sub-pixel points (K, 2) where the edge from a to b crosses mid-grey, sampled along 12-88 % of it.

    Each profile runs from the middle of the black border cell (half a cell inside) to the quiet zone
    (half a cell outside); its two ends give the dark and light levels.
    """
    length = float(np.linalg.norm(b - a))
    d = (b - a) / length
    normal = np.array([-d[1], d[0]])
    ts = np.linspace(0.12, 0.88, max(_MIN_SAMPLES, int(length / 2)))
    ss = np.arange(-half_cell, half_cell + 1e-9, _STEP_PX)
    P = a + ts[:, None, None] * (b - a) + ss[None, :, None] * normal
    prof = cv2.remap(gray, P[..., 0].astype(np.float32), P[..., 1].astype(np.float32), cv2.INTER_LINEAR).astype(float)
    ends = np.stack([prof[:, :2].mean(axis=1), prof[:, -2:].mean(axis=1)])
    lo, hi = ends.min(axis=0), ends.max(axis=0)
    p = prof - ((lo + hi) / 2)[:, None]
    change = np.signbit(p[:, :-1]) != np.signbit(p[:, 1:])
    ok = (change.sum(axis=1) == 1) & (hi - lo >= _MIN_CONTRAST)
    rows = np.flatnonzero(ok)
    k = np.argmax(change[rows], axis=1)
    frac = p[rows, k] / (p[rows, k] - p[rows, k + 1])
    s_edge = ss[k] + frac * _STEP_PX
    return a + ts[rows, None] * (b - a) + s_edge[:, None] * normal


def _fit_line(points: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """Total-least-squares line (point, unit direction), refitted without points > 3 robust sigma (and > 0.3 px) off."""
    pts = points
    for _ in range(3):
        if len(pts) < _MIN_SAMPLES:
            return None
        centre = pts.mean(axis=0)
        direction = np.linalg.svd(pts - centre)[2][0]
        dist = np.abs((pts - centre) @ np.array([-direction[1], direction[0]]))
        keep = dist <= max(0.3, 3.0 * 1.4826 * np.median(dist))
        if keep.all():
            break
        pts = pts[keep]
    return centre, direction


def _undistort(points: np.ndarray, camera: CameraModel) -> np.ndarray:
    return cv2.undistortPoints(points.reshape(-1, 1, 2), camera.K, camera.dist_coeffs, P=camera.K).reshape(-1, 2)


def refine_marker_corners(
    gray: np.ndarray, corners: np.ndarray, bits: int, camera: CameraModel | None = None, passes: int = 2
) -> np.ndarray:
    """Corners (4, 2) re-estimated from the marker's four outer edges; the input corners when a side is
    too short or too few clean edge samples are found. `bits` is the marker's cells per side (with border).

    A second pass samples along the refined sides (under blur the detector's corners sit a pixel or
    more inside the marker). The marker needs a white quiet zone of at least half a cell.
    """
    c = np.asarray(corners, dtype=float).reshape(4, 2)
    out = c
    for _ in range(passes):
        refined = _refine_once(gray, out, bits, camera)
        if (
            refined is None or np.max(np.linalg.norm(refined - c, axis=1)) > 3.0
        ):  # lines met far off: keep the detector's
            return out
        out = refined
    return out


def _refine_once(gray: np.ndarray, c: np.ndarray, bits: int, camera: CameraModel | None) -> np.ndarray | None:
    sides = np.linalg.norm(np.roll(c, -1, axis=0) - c, axis=1)
    if sides.min() < _MIN_SIDE_PX:
        return None
    half_cell = 0.5 * sides.min() / bits
    distorted = camera if camera is not None and np.any(camera.dist_coeffs) else None  # a lens that bends edges
    lines = []
    for i in range(4):
        pts = _edge_points(gray, c[i], c[(i + 1) % 4], half_cell)
        line = _fit_line(_undistort(pts, distorted) if distorted is not None and len(pts) else pts)
        if line is None:
            return None
        lines.append(line)
    out = np.empty((4, 2))
    for i in range(4):
        (p1, d1), (p2, d2) = lines[i - 1], lines[i]
        A = np.column_stack([d1, -d2])
        if abs(np.linalg.det(A)) < 1e-6:
            return None
        out[i] = p1 + np.linalg.solve(A, p2 - p1)[0] * d1
    if distorted is not None:
        normalized = cv2.undistortPoints(out.reshape(-1, 1, 2), distorted.K, np.zeros(5)).reshape(-1, 2)
        out = distorted.project(np.column_stack([normalized, np.ones(4)]))
    return out
