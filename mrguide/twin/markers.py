"""Fiducial markers and the HMD camera in the twin.

Markers and boards are thin textured slabs whose printed face carries the OpenCV-generated image with a
white quiet zone; the texture coordinates are set per vertex, so a marker corner in the image lands on
the corresponding 3D corner. `render` samples each pixel over its area (supersampling), as a real sensor
integrates light, so sub-pixel corner refinement has grey levels to work with. `TwinHmd` is the HMD:
a head-mounted camera rendering the scene, reporting its pose in the HMD world frame like head tracking.
"""

from __future__ import annotations

import atexit
import logging
import shutil
import tempfile
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Protocol

import cv2
import numpy as np
import pybullet as pb

from mrguide.calibration.boards import Board, printable_board, printable_marker, single_marker_corners
from mrguide.calibration.camera_model import CameraModel
from mrguide.calibration.config import CalibrationConfig, DetectorConfig, HmdNoiseConfig, check_points
from mrguide.calibration.detection import MarkerDetector, get_dictionary
from mrguide.calibration.hmd import HmdFrame, with_calibration_error, with_tracking_noise
from mrguide.calibration.pose_sources import MarkerPoseSource
from mrguide.calibration.procedure import CalibrationRun, calibrate_frames
from mrguide.calibration.se3 import apply, invert, make_T, rotation_from_rpy_deg
from mrguide.calibration.targets import layout_from_config
from mrguide.config import ConfigError, Range, check_ranges
from mrguide.twin.camera import Camera, Intrinsics, look_at

log = logging.getLogger(__name__)

#: HoloLens 2 photo/video camera in its 1280x720 mode: 64.69 deg horizontal field of view
#: (Microsoft, "Locatable camera overview"), i.e. f = 640 / tan(32.345 deg) = 1011 px.
HOLOLENS2_PV = Intrinsics(width=1280, height=720, fx=1011.0, fy=1011.0, cx=639.5, cy=359.5)
MARKER_THICKNESS = 0.0005  # m; a printed sticker, thick enough to avoid z-fighting with the surface under it
_TEXTURE_DIR: Path | None = None


#: Print resolution of markers and boards (px/m): 5 cm markers 12.5 mm apart come out in whole pixels.
PX_PER_M = 4000.0


@dataclass(frozen=True)
class Sheet:
    """A print to put on a slab: its image, the face-frame corners of the image (TL, TR, BR, BL) and a name that
    says what is printed (its texture file is cached under that name)."""

    image: np.ndarray
    corners: np.ndarray
    name: str

    def texture_path(self) -> str:
        """The image as a colour PNG in this process's texture folder (written once per name)."""
        global _TEXTURE_DIR
        if _TEXTURE_DIR is None:
            _TEXTURE_DIR = Path(tempfile.mkdtemp(prefix="mrguide-markers-"))
            atexit.register(shutil.rmtree, _TEXTURE_DIR, ignore_errors=True)
        path = _TEXTURE_DIR / f"{self.name}.png"
        if not path.exists():
            rgb = cv2.cvtColor(self.image, cv2.COLOR_GRAY2BGR) if self.image.ndim == 2 else self.image
            cv2.imwrite(str(path), rgb)
        return str(path)


def marker_sheet(
    dictionary: str, marker_id: int, size_m: float, quiet_zone_m: float | None = None, px_per_m: float = PX_PER_M
) -> Sheet:
    """One printed marker with its white quiet zone (default: a quarter of the marker size), in the marker frame
    (z out of the print, corner 0 at (-s/2, s/2))."""
    quiet = size_m / 4.0 if quiet_zone_m is None else quiet_zone_m
    image = printable_marker(get_dictionary(dictionary), marker_id, size_m, quiet, px_per_m)
    corners = single_marker_corners(size_m + 2 * quiet)
    return Sheet(image, corners, f"marker-{dictionary}-{marker_id}-{size_m}-{quiet}-{px_per_m}")


def board_sheet(board: Board, px_per_m: float = PX_PER_M) -> Sheet:
    """The printed board with its white margin, in the board frame (see `mrguide.calibration.boards`)."""
    c, m = board.cfg, board.cfg.margin_m
    w, h = board.size_m
    corners = np.array([[-m, -m, 0.0], [w + m, -m, 0.0], [w + m, h + m, 0.0], [-m, h + m, 0.0]])
    name = f"board-{c.kind}-{c.columns}x{c.rows}-{c.marker_size_m}-{c.separation_m}-{c.square_size_m}-{c.first_id}-{m}-{px_per_m}"
    return Sheet(printable_board(board, px_per_m), corners, name)


def _quat_xyzw(R: np.ndarray) -> list[float]:
    """PyBullet quaternion (x, y, z, w) of a rotation matrix."""
    w = np.sqrt(max(0.0, 1.0 + np.trace(R))) / 2.0
    if w > 1e-6:
        return [(R[2, 1] - R[1, 2]) / (4 * w), (R[0, 2] - R[2, 0]) / (4 * w), (R[1, 0] - R[0, 1]) / (4 * w), w]
    i = int(np.argmax(np.diag(R)))
    j, k = (i + 1) % 3, (i + 2) % 3
    q = np.zeros(4)
    q[i] = np.sqrt(max(0.0, 1.0 + R[i, i] - R[j, j] - R[k, k])) / 2.0
    q[j] = (R[j, i] + R[i, j]) / (4 * q[i])
    q[k] = (R[k, i] + R[i, k]) / (4 * q[i])
    q[3] = (R[k, j] - R[j, k]) / (4 * q[i])
    return q.tolist()


def slab_mesh(corners: np.ndarray, thickness: float, tex_shape: tuple[int, int]):
    """Vertices, indices, normals and uvs of a slab whose printed face is the quad `corners` (TL, TR, BR, BL of
    the image); the slab extends `thickness` behind the face. Only the printed face is textured; the other
    faces sample the image's top-left (white quiet-zone) texel."""
    tl, tr, _br, bl = corners
    n = np.cross(bl - tl, tr - tl)
    n /= np.linalg.norm(n)
    back = corners - n * max(thickness, 1e-5)
    h, w = tex_shape
    white = [0.5 / w, 1.0 - 0.5 / h]
    centre = (corners.mean(axis=0) + back.mean(axis=0)) / 2.0
    faces: list[tuple[np.ndarray, list[list[float]]]] = [(corners, [[0, 1], [1, 1], [1, 0], [0, 0]])]
    faces.append((back[::-1], [white] * 4))
    for a, b in ((0, 1), (1, 2), (2, 3), (3, 0)):
        faces.append((np.array([corners[a], back[a], back[b], corners[b]]), [white] * 4))
    vertices: list[list[float]] = []
    indices: list[int] = []
    normals: list[list[float]] = []
    uvs: list[list[float]] = []
    for quad, quad_uv in faces:
        normal = np.cross(quad[1] - quad[0], quad[2] - quad[0])
        normal /= np.linalg.norm(normal)
        if normal @ (quad.mean(axis=0) - centre) < 0:  # wind counter-clockwise seen from outside
            quad, quad_uv, normal = quad[::-1], quad_uv[::-1], -normal
        base = len(vertices)
        vertices += quad.tolist()
        uvs += [list(uv) for uv in quad_uv]
        normals += [normal.tolist()] * 4
        indices += [base, base + 1, base + 2, base, base + 2, base + 3]
    return vertices, indices, normals, uvs


def add_textured_slab(client: int, sheet: Sheet, T_base_face: np.ndarray, thickness: float) -> int:
    """A static, visual-only body showing `sheet` on its corners' quad (in the face frame placed at `T_base_face`),
    the slab extending `thickness` behind the face; returns its body id."""
    vertices, indices, normals, uvs = slab_mesh(sheet.corners, thickness, sheet.image.shape[:2])
    vis = pb.createVisualShape(
        pb.GEOM_MESH, vertices=vertices, indices=indices, normals=normals, uvs=uvs, physicsClientId=client
    )
    T = np.asarray(T_base_face, dtype=float)
    body = pb.createMultiBody(0, -1, vis, T[:3, 3].tolist(), _quat_xyzw(T[:3, :3]), physicsClientId=client)
    tex = pb.loadTexture(sheet.texture_path(), physicsClientId=client)
    pb.changeVisualShape(body, -1, textureUniqueId=tex, rgbaColor=[1, 1, 1, 1], physicsClientId=client)
    return body


def add_marker_plane(
    client: int,
    dictionary: str,
    marker_id: int,
    size_m: float,
    T_base_marker: np.ndarray,
    quiet_zone_m: float | None = None,
    thickness_m: float = MARKER_THICKNESS,
    px_per_m: float = PX_PER_M,
) -> int:
    """A printed marker whose face has pose `T_base_marker` (marker frame: z out of the print, corner 0 at
    (-s/2, s/2)); the slab extends `thickness_m` behind the face. Returns the body id.

    A marker lying on a surface at height z needs its face at z + thickness_m (to avoid z-fighting).
    `quiet_zone_m` defaults to a quarter of the marker size.
    """
    sheet = marker_sheet(dictionary, marker_id, size_m, quiet_zone_m, px_per_m)
    return add_textured_slab(client, sheet, T_base_marker, thickness_m)


def add_board(client: int, board: Board, T_base_board: np.ndarray, px_per_m: float = PX_PER_M) -> int:
    """The printed board, its pattern at `T_base_board` (board frame: see `mrguide.calibration.boards`), as a
    slab `board.cfg.thickness_m` thick behind the printed face. For a board on the table use
    `board_pose_on_table((x, y, thickness), yaw)`. Returns the body id."""
    return add_textured_slab(client, board_sheet(board, px_per_m), T_base_board, board.cfg.thickness_m)


def marker_on_cube_top(cube_size: float, thickness_m: float = MARKER_THICKNESS) -> np.ndarray:
    """T_object_marker of a marker stuck on the top face of a cube (object frame at the cube centre, z up)."""
    return make_T(np.eye(3), np.array([0.0, 0.0, cube_size / 2.0 + thickness_m]))


class MarkerOnBody:
    """A marker that rides on a (moving) body: call `update()` before rendering to move it along."""

    def __init__(
        self,
        client: int,
        body: int,
        T_body_marker: np.ndarray,
        dictionary: str,
        marker_id: int,
        size_m: float,
        quiet_zone_m: float | None = None,
        link: int = -1,
    ):
        self.client, self.body, self.link = client, body, link
        self.T_body_marker = np.asarray(T_body_marker, dtype=float)
        self.marker_body = add_marker_plane(client, dictionary, marker_id, size_m, self.T_base_marker(), quiet_zone_m)

    def T_base_body(self) -> np.ndarray:
        if self.link < 0:
            pos, orn = pb.getBasePositionAndOrientation(self.body, physicsClientId=self.client)
        else:
            pos, orn = pb.getLinkState(
                self.body, self.link, computeForwardKinematics=True, physicsClientId=self.client
            )[4:6]
        R = np.asarray(pb.getMatrixFromQuaternion(orn), dtype=float).reshape(3, 3)
        return make_T(R, pos)

    def T_base_marker(self) -> np.ndarray:
        return self.T_base_body() @ self.T_body_marker

    def update(self) -> None:
        T = self.T_base_marker()
        pb.resetBasePositionAndOrientation(
            self.marker_body, T[:3, 3].tolist(), _quat_xyzw(T[:3, :3]), physicsClientId=self.client
        )


def render(camera: Camera, supersample: int = 2) -> np.ndarray:
    """RGB image of `camera`, each pixel the mean of supersample x supersample samples over its area."""
    if supersample == 1:
        return camera.render()
    k, s = camera.intrinsics, supersample
    fine = Intrinsics(k.width * s, k.height * s, k.fx * s, k.fy * s, k.cx * s + (s - 1) / 2, k.cy * s + (s - 1) / 2)
    rgb = Camera(camera.client, camera.T_base_cam, fine, camera.near, camera.far).render()
    return cv2.resize(rgb, (k.width, k.height), interpolation=cv2.INTER_AREA)


class TwinHmd:
    """The HMD in the twin: its camera renders the scene; head tracking reports T_hmd_cam exactly.

    `T_base_hmd` is where the HMD's world frame truly is in the robot base frame (unknown to the HMD;
    the calibration estimates it). Tracking noise is added by `mrguide.calibration.hmd.with_tracking_noise`.
    `attached` markers (riding on moving bodies) are moved along before every frame.
    """

    def __init__(
        self,
        client: int,
        T_base_hmd: np.ndarray,
        T_base_cam: np.ndarray,
        intrinsics: Intrinsics = HOLOLENS2_PV,
        supersample: int = 2,
        near: float = 0.05,
        far: float = 5.0,
        attached: Sequence[MarkerOnBody] = (),
    ):
        self.client = client
        self.attached = list(attached)
        self.T_base_hmd = np.asarray(T_base_hmd, dtype=float)
        self.intrinsics, self.supersample, self.near, self.far = intrinsics, supersample, near, far
        self.camera_model = CameraModel.from_pinhole(intrinsics)
        self.move_to(T_base_cam)

    def move_to(self, T_base_cam: np.ndarray) -> None:
        """Put the head so that the camera is at `T_base_cam`."""
        self.camera = Camera(self.client, np.asarray(T_base_cam, dtype=float), self.intrinsics, self.near, self.far)

    def look_from(self, eye, target, up=(0.0, 0.0, 1.0)) -> None:
        self.move_to(look_at(np.asarray(eye), np.asarray(target), np.asarray(up)))

    def T_hmd_cam(self) -> np.ndarray:
        return invert(self.T_base_hmd) @ self.camera.T_base_cam

    def frame(self) -> HmdFrame:
        """The current image with the (exact) head-tracked camera pose."""
        for marker in self.attached:
            marker.update()
        return HmdFrame(render(self.camera, self.supersample), self.T_hmd_cam())


class HmdCamera(Protocol):
    """An HMD as the calibration and the marker pose source use it: frames with head-tracked poses, its camera's
    model, and where it looks from."""

    camera_model: CameraModel

    def frame(self) -> HmdFrame: ...

    def look_from(self, eye, target, up=(0.0, 0.0, 1.0)) -> None: ...


def hmd_marker_pose_source(
    hmd: HmdCamera,
    T_base_hmd_estimate: np.ndarray,
    detector_cfg: DetectorConfig,
    marker_id: int,
    offset_marker_to_object: np.ndarray,
    noise: HmdNoiseConfig = HmdNoiseConfig(),
) -> MarkerPoseSource:
    """The object pose source of sim-to-real condition 3: the HMD camera sees the object's marker, head
    tracking (with `noise.tracking_*`) places the camera in the HMD frame, and the calibration estimate
    (moved by `noise.calibration_*`) maps it to the robot base frame."""
    return MarkerPoseSource(
        frames=with_tracking_noise(hmd.frame, noise),
        detector=MarkerDetector(detector_cfg),
        camera=hmd.camera_model,
        T_base_hmd=with_calibration_error(T_base_hmd_estimate, noise),
        marker_id=marker_id,
        offset_marker_to_object=offset_marker_to_object,
    )


def annotations_of_body(
    client: int, body: int, T_base_hmd: np.ndarray, sigma_m: float, rng: np.random.Generator
) -> Callable[[], np.ndarray]:
    """A simulated MR annotator: the body's position in the HMD frame, placed with N(0, sigma_m^2) error per axis."""
    T_hmd_base = invert(np.asarray(T_base_hmd, dtype=float))

    def annotate() -> np.ndarray:
        pos, _ = pb.getBasePositionAndOrientation(body, physicsClientId=client)
        return apply(T_hmd_base, np.asarray(pos)) + (rng.normal(0.0, sigma_m, 3) if sigma_m > 0 else 0.0)

    return annotate


@dataclass(frozen=True)
class TwinCalibrationConfig:
    """`[calibration_twin]`: the simulated HMD that `mrguide calibrate --twin` calibrates."""

    hmd_xyz: tuple[float, float, float] = (1.3, 0.4, 0.45)  # HMD world origin in the base frame (where it booted)
    hmd_rpy_deg: tuple[float, float, float] = (90.0, 0.0, 160.0)  # its orientation (HoloLens worlds are y-up)
    views: tuple[tuple[float, float, float], ...] = (  # camera positions (m, base frame), 0.6-0.9 m from the board
        (0.95, 0.15, 0.55),
        (0.85, 0.55, 0.50),
        (0.80, -0.20, 0.55),
        (1.05, 0.35, 0.60),
    )
    look_at: tuple[float, float, float] = (0.48, 0.13, 0.0)  # where the wearer looks (the board centre)
    intrinsics: Intrinsics = HOLOLENS2_PV
    supersample: Annotated[int, Range(1, 8)] = 2

    def __post_init__(self) -> None:
        if not self.views:
            raise ConfigError("calibration_twin.views: at least one camera position is needed")
        check_points("calibration_twin.views", self.views)
        check_ranges(self, "calibration_twin")

    @property
    def T_base_hmd(self) -> np.ndarray:
        return make_T(rotation_from_rpy_deg(*self.hmd_rpy_deg), np.asarray(self.hmd_xyz, dtype=float))


def add_targets(client: int, cfg: CalibrationConfig) -> list[int]:
    """Put the configured calibration targets (board and single markers) into the scene; their body ids."""
    detector = MarkerDetector(cfg.detector)
    layout = layout_from_config(cfg, detector)
    bodies = []
    if layout.board is not None:
        assert layout.T_base_board is not None  # a layout with a board has its pose (layout_from_config)
        bodies.append(add_board(client, layout.board, layout.T_base_board))
    for marker_id, T_base_marker in layout.markers.items():
        bodies.append(
            add_marker_plane(client, cfg.detector.dictionary, marker_id, cfg.detector.marker_size_m, T_base_marker)
        )
    return bodies


def calibrate_twin_hmd(
    hmd: TwinHmd, cfg: CalibrationConfig, views, look_at_point, noise: HmdNoiseConfig = HmdNoiseConfig()
) -> CalibrationRun:
    """Run the calibration procedure in the twin: the targets are put on the table, the HMD looks at them
    from each view (tracking noise per `noise`), the frames are registered, and the targets are removed."""
    bodies = add_targets(hmd.client, cfg)
    try:
        shots = calibration_shots(hmd, views, look_at_point, noise)
    finally:
        for body in bodies:
            pb.removeBody(body, physicsClientId=hmd.client)
    return calibrate_frames(shots, cfg, hmd.camera_model)


def calibration_shots(
    hmd: HmdCamera, views, look_at_point, noise: HmdNoiseConfig
) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """The calibration's frames: the HMD looks at `look_at_point` from each of `views` (tracking noise per `noise`);
    (label, image, T_hmd_cam) per view."""
    frames = with_tracking_noise(hmd.frame, noise)
    shots = []
    for i, eye in enumerate(views):
        hmd.look_from(eye, look_at_point)
        f = frames()
        shots.append((f"view{i}", f.image, f.T_hmd_cam))
    return shots
