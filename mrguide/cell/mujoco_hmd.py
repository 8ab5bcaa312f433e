"""The HMD of the MuJoCo cell, rendered by MuJoCo's own offscreen renderer.

The scene is compiled from the same robot description as the MuJoCo cell (`mujoco_cell.model.arm_spec`: the URDF's
collision meshes, which are what MuJoCo draws), with the table, the part as a mocap body carrying its printed marker,
and the calibration targets (board and single markers) in geom group 3, drawn only while the HMD calibrates. Markers are
slabs whose printed face carries the OpenCV-generated image through per-vertex texture coordinates, as in the
PyBullet HMD (`twin.markers.slab_mesh`), so a marker corner in the image lands on its 3D corner.

The camera is a world camera moved per frame (`model.cam_pos`/`cam_quat`); MuJoCo draws a centred pinhole with
square pixels from its vertical field of view, so the HMD's intrinsics must be such (the HoloLens 2 PV mode is).
Offscreen rendering needs an OpenGL context without a display: `MUJOCO_GL=egl` (Debian: libegl1, libegl-mesa0,
libgl1-mesa-dri) or `osmesa` (libosmesa6); set it before `mujoco` is imported.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import cv2
import mujoco
import numpy as np
from numpy.typing import ArrayLike

from mrguide.calibration.camera_model import CameraModel
from mrguide.calibration.config import CalibrationConfig, HmdNoiseConfig
from mrguide.calibration.detection import MarkerDetector
from mrguide.calibration.hmd import HmdFrame
from mrguide.calibration.procedure import CalibrationRun, calibrate_frames
from mrguide.calibration.se3 import invert
from mrguide.calibration.targets import layout_from_config
from mrguide.cell.rendering import OFFSCREEN_GL_HELP
from mrguide.cell_layout import CupConfig
from mrguide.config import ConfigError
from mrguide.mujoco_cell.config import MujocoCellConfig
from mrguide.mujoco_cell.model import add_table, arm_spec
from mrguide.robot import RobotSpec
from mrguide.twin.camera import Intrinsics, look_at
from mrguide.twin.markers import (
    HOLOLENS2_PV,
    MARKER_THICKNESS,
    Sheet,
    board_sheet,
    calibration_shots,
    marker_on_cube_top,
    marker_sheet,
    slab_mesh,
)

#: The geom group of the calibration targets (MuJoCo draws groups 0-2 unless told otherwise).
TARGET_GROUP = 3
#: OpenCV camera frame (x right, y down, z forward) -> MuJoCo camera frame (x right, y up, looking along -z).
_CV_TO_MJ = np.diag([1.0, -1.0, -1.0])


def _quat_wxyz(R: np.ndarray) -> np.ndarray:
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.ascontiguousarray(R, dtype=float).ravel())
    return quat


def _add_print(s: mujoco.MjSpec, body, sheet: Sheet, T: np.ndarray, thickness: float, group: int) -> None:
    """A slab on `body` at pose `T` (body frame) whose face shows `sheet`, `thickness` deep."""
    vertices, indices, normals, uvs = slab_mesh(sheet.corners, thickness, sheet.image.shape[:2])
    path = Path(sheet.texture_path())
    s.compiler.texturedir = str(path.parent)  # the arm's compiler strips paths: textures are found by name there
    s.add_texture(name=sheet.name, type=mujoco.mjtTexture.mjTEXTURE_2D, file=path.name)
    material = s.add_material(name=sheet.name, specular=0.0, shininess=0.0, reflectance=0.0)
    material.textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = sheet.name
    s.add_mesh(
        name=sheet.name,
        uservert=np.ravel(vertices).tolist(),
        usernormal=np.ravel(normals).tolist(),
        usertexcoord=np.ravel(np.asarray(uvs) * (1.0, -1.0) + (0.0, 1.0)).tolist(),  # MuJoCo's v runs the other way
        userface=list(indices),
    )
    body.add_geom(
        name=sheet.name,
        type=mujoco.mjtGeom.mjGEOM_MESH,
        meshname=sheet.name,
        material=sheet.name,
        pos=T[:3, 3],
        quat=_quat_wxyz(T[:3, :3]),
        contype=0,
        conaffinity=0,
        group=group,
        mass=0.0,
    )


def _add_targets(s: mujoco.MjSpec, cfg: CalibrationConfig) -> None:
    """The configured calibration board and single markers on the table, in TARGET_GROUP."""
    layout = layout_from_config(cfg, MarkerDetector(cfg.detector))
    if layout.board is not None:
        assert layout.T_base_board is not None  # a layout with a board has its pose
        sheet = board_sheet(layout.board)
        _add_print(s, s.worldbody, sheet, layout.T_base_board, layout.board.cfg.thickness_m, TARGET_GROUP)
    for marker_id, T in layout.markers.items():
        sheet = marker_sheet(cfg.detector.dictionary, marker_id, cfg.detector.marker_size_m)
        _add_print(s, s.worldbody, sheet, T, MARKER_THICKNESS, TARGET_GROUP)


class RendererError(RuntimeError):
    """MuJoCo's offscreen renderer could not start (no OpenGL context without a display)."""


def _renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    try:
        return mujoco.Renderer(model, height, width)
    except Exception as exc:
        backend = os.environ.get("MUJOCO_GL", "glfw (MUJOCO_GL unset)")
        raise RendererError(
            f"the renderer could not start with MUJOCO_GL={backend}: {exc}. {OFFSCREEN_GL_HELP}"
        ) from exc


class MujocoHmd:
    """The HMD in the MuJoCo cell: its camera renders the scene with MuJoCo; head tracking reports T_hmd_cam
    exactly (noise is added by `with_tracking_noise`). The same interface as the PyBullet `TwinHmd`."""

    def __init__(
        self,
        spec: RobotSpec,
        cup: CupConfig,
        part_size: float,
        cfg: CalibrationConfig,
        marker_id: int,
        T_base_hmd: np.ndarray,
        intrinsics: Intrinsics = HOLOLENS2_PV,
        supersample: int = 2,
    ):
        k = intrinsics
        if abs(k.fx - k.fy) > 1e-6 or abs(k.cx - (k.width - 1) / 2) > 1e-6 or abs(k.cy - (k.height - 1) / 2) > 1e-6:
            raise ConfigError(
                "the MuJoCo HMD renders a centred pinhole with square pixels: intrinsics need fx = fy, "
                f"cx = (width - 1)/2 and cy = (height - 1)/2, got {k}"
            )
        s = arm_spec(spec, MujocoCellConfig(), cup)
        s.compiler.discardvisual = False  # the URDF's visual meshes were skipped when parsing; keep the prints
        add_table(s)
        part = s.worldbody.add_body(name="part", mocap=True)
        h = 0.5 * part_size
        part.add_geom(name="part", type=mujoco.mjtGeom.mjGEOM_BOX, size=[h, h, h], rgba=[0.85, 0.1, 0.1, 1])
        sheet = marker_sheet(cfg.detector.dictionary, marker_id, cfg.detector.marker_size_m)
        self.T_part_marker = marker_on_cube_top(part_size)
        _add_print(s, part, sheet, self.T_part_marker, MARKER_THICKNESS, 0)
        _add_targets(s, cfg)
        s.worldbody.add_light(name="overhead", pos=[0.5, 0.0, 1.6], dir=[0.0, 0.0, -1.0], castshadow=False)
        s.worldbody.add_camera(name="hmd", fovy=math.degrees(2.0 * math.atan(k.height / 2.0 / k.fy)))
        s.visual.global_.offwidth = k.width * supersample  # the largest image drawn: the calibration's
        s.visual.global_.offheight = k.height * supersample
        self.model = s.compile()
        self.data = mujoco.MjData(self.model)
        self._arm_qpos = np.array([self.model.joint(n).qposadr[0] for n in spec.joint_names])
        self._camera = self.model.camera("hmd").id
        self._option = mujoco.MjvOption()
        self.T_base_hmd = np.asarray(T_base_hmd, dtype=float)
        self.intrinsics, self.supersample = intrinsics, supersample
        self.camera_model = CameraModel.from_pinhole(intrinsics)
        self._renderer: tuple[int, mujoco.Renderer] | None = None  # (supersample, renderer): one context at a time
        self.move_to(np.eye(4))

    def move_to(self, T_base_cam: np.ndarray) -> None:
        """Put the head so that the camera (OpenCV frame) is at `T_base_cam`."""
        self.T_base_cam = np.asarray(T_base_cam, dtype=float)
        self.model.cam_pos[self._camera] = self.T_base_cam[:3, 3]
        self.model.cam_quat[self._camera] = _quat_wxyz(self.T_base_cam[:3, :3] @ _CV_TO_MJ)

    def look_from(self, eye, target, up=(0.0, 0.0, 1.0)) -> None:
        self.move_to(look_at(np.asarray(eye), np.asarray(target), np.asarray(up)))

    def pose(self, part_pos: ArrayLike, part_quat_xyzw: ArrayLike, q: ArrayLike) -> None:
        """Put the part and the arm where the cell has them (the part's quaternion in PyBullet's x, y, z, w)."""
        x, y, z, w = np.asarray(part_quat_xyzw, dtype=float)
        self.data.mocap_pos[0] = part_pos
        self.data.mocap_quat[0] = (w, x, y, z)
        self.data.qpos[self._arm_qpos] = q

    def show_targets(self, shown: bool) -> None:
        """Draw the calibration targets (while calibrating) or not."""
        self._option.geomgroup[TARGET_GROUP] = int(shown)

    def T_hmd_cam(self) -> np.ndarray:
        return invert(self.T_base_hmd) @ self.T_base_cam

    def render(self) -> np.ndarray:
        """RGB image, each pixel the mean of supersample x supersample samples over its area."""
        k, s = self.intrinsics, self.supersample
        if (
            self._renderer is None or self._renderer[0] != s
        ):  # each context holds an offscreen buffer of the largest size
            self.close()
            self._renderer = (s, _renderer(self.model, k.height * s, k.width * s))
        renderer = self._renderer[1]
        mujoco.mj_kinematics(self.model, self.data)
        mujoco.mj_camlight(self.model, self.data)
        renderer.update_scene(self.data, camera=self._camera, scene_option=self._option)
        rgb = renderer.render()
        return rgb if s == 1 else cv2.resize(rgb, (k.width, k.height), interpolation=cv2.INTER_AREA)

    def frame(self) -> HmdFrame:
        """The current image with the (exact) head-tracked camera pose."""
        return HmdFrame(self.render(), self.T_hmd_cam())

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer[1].close()
            self._renderer = None


def calibrate_mujoco_hmd(
    hmd: MujocoHmd, cfg: CalibrationConfig, views, look_at_point, noise: HmdNoiseConfig = HmdNoiseConfig()
) -> CalibrationRun:
    """The calibration procedure in the MuJoCo cell: the targets are shown, the HMD looks at them from each view
    (tracking noise per `noise`), the frames are registered, and the targets are hidden again."""
    hmd.show_targets(True)
    try:
        shots = calibration_shots(hmd, views, look_at_point, noise)
    finally:
        hmd.show_targets(False)
    return calibrate_frames(shots, cfg, hmd.camera_model)
