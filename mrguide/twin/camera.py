"""A pinhole camera in the twin: pose and intrinsics as OpenCV uses them, rendered by PyBullet.

The camera frame follows OpenCV (x right, y down, z forward). `T_base_cam` maps camera coordinates to
the robot base frame. Images come from PyBullet's TinyRenderer, so no display is needed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated, Literal, overload

import numpy as np
import pybullet as pb

from mrguide.config import ConfigError, Range, check_number, check_ranges

#: Largest rendered image side (px).
MAX_IMAGE_SIDE = 16384


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics in pixels, no distortion (the renderer has none)."""

    width: Annotated[int, Range(1, MAX_IMAGE_SIDE, " px")] = 640
    height: Annotated[int, Range(1, MAX_IMAGE_SIDE, " px")] = 480
    fx: Annotated[float, Range(1.0, 1e6, " px")] = 600.0
    fy: Annotated[float, Range(1.0, 1e6, " px")] = 600.0
    cx: float = 320.0
    cy: float = 240.0

    def __post_init__(self) -> None:
        check_ranges(self, "intrinsics")

    @property
    def K(self) -> np.ndarray:
        """3x3 camera matrix."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])


@dataclass(frozen=True)
class CameraConfig:
    """Camera pose as eye/target/up in the base frame (m) plus intrinsics and clipping planes."""

    eye: tuple[float, float, float] = (1.25, 0.10, 0.75)
    target: tuple[float, float, float] = (0.48, 0.10, 0.0)
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)
    intrinsics: Intrinsics = field(default_factory=Intrinsics)
    near: Annotated[float, Range(1e-3, 10.0, " m")] = 0.05  # in [0.001, 10]
    far: float = 5.0  # m; beyond `near`, at most 1000

    def __post_init__(self) -> None:
        check_ranges(self, "camera")
        check_number("camera.far", self.far, self.near * (1 + 1e-6), 1000.0, " m (beyond camera.near)")


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray) -> np.ndarray:
    """T_base_cam for an OpenCV camera at `eye` looking at `target` with image-up roughly along `up`."""
    eye, target, up = (np.asarray(v, dtype=float) for v in (eye, target, up))
    z = target - eye
    if np.linalg.norm(z) < 1e-9:
        raise ConfigError("camera: eye and target coincide")
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    if np.linalg.norm(x) < 1e-9:
        raise ConfigError("camera: viewing direction is parallel to `up`")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    T = np.eye(4)
    T[:3, :3] = np.column_stack([x, y, z])
    T[:3, 3] = eye
    return T


_T_CV_GL = np.diag([1.0, -1.0, -1.0, 1.0])  # OpenCV camera axes -> OpenGL camera axes
#: TinyRenderer rasterizes one row above the pinhole model (measured: -1.00 px, std 0.1 px).
_ROW_OFFSET = 1.0


class Camera:
    """Renders RGB (and depth) images of a PyBullet scene from a fixed pose."""

    def __init__(
        self, client: int, T_base_cam: np.ndarray, intrinsics: Intrinsics, near: float = 0.05, far: float = 5.0
    ):
        self.client = client
        self.T_base_cam = np.asarray(T_base_cam, dtype=float)
        self.intrinsics = intrinsics
        self.near, self.far = near, far
        view = np.linalg.inv(self.T_base_cam @ _T_CV_GL)
        self._view = view.T.reshape(-1).tolist()  # column-major for OpenGL
        self._proj = self._projection().T.reshape(-1).tolist()

    @classmethod
    def from_config(cls, client: int, cfg: CameraConfig) -> Camera:
        return cls(
            client,
            look_at(np.array(cfg.eye), np.array(cfg.target), np.array(cfg.up)),
            cfg.intrinsics,
            cfg.near,
            cfg.far,
        )

    def _projection(self) -> np.ndarray:
        k, n, f = self.intrinsics, self.near, self.far
        w, h = k.width, k.height
        return np.array(
            [
                [2 * k.fx / w, 0.0, 1.0 - 2 * k.cx / w, 0.0],
                [0.0, 2 * k.fy / h, 2 * (k.cy + _ROW_OFFSET) / h - 1.0, 0.0],
                [0.0, 0.0, -(f + n) / (f - n), -2 * f * n / (f - n)],
                [0.0, 0.0, -1.0, 0.0],
            ]
        )

    @overload
    def render(self, with_depth: Literal[False] = False) -> np.ndarray: ...

    @overload
    def render(self, with_depth: Literal[True]) -> tuple[np.ndarray, np.ndarray]: ...

    def render(self, with_depth: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """RGB image (H, W, 3) uint8; with `with_depth`, also metric depth along the optical axis (H, W)."""
        k = self.intrinsics
        _, _, rgba, depth_buf, _ = pb.getCameraImage(
            k.width,
            k.height,
            viewMatrix=self._view,
            projectionMatrix=self._proj,
            renderer=pb.ER_TINY_RENDERER,
            flags=pb.ER_NO_SEGMENTATION_MASK,
            physicsClientId=self.client,
        )
        rgb = np.asarray(rgba, dtype=np.uint8).reshape(k.height, k.width, 4)[:, :, :3].copy()
        if not with_depth:
            return rgb
        zb = np.asarray(depth_buf, dtype=float).reshape(k.height, k.width)
        depth = self.far * self.near / (self.far - (self.far - self.near) * zb)
        return rgb, depth

    def project(self, points_base: np.ndarray) -> np.ndarray:
        """Pixel coordinates (N, 2) of points given in the base frame (N, 3)."""
        pts = np.atleast_2d(np.asarray(points_base, dtype=float))
        T_cam_base = np.linalg.inv(self.T_base_cam)
        pc = pts @ T_cam_base[:3, :3].T + T_cam_base[:3, 3]
        uvw = pc @ self.intrinsics.K.T
        return uvw[:, :2] / uvw[:, 2:3]
