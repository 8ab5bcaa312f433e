"""The MuJoCo cell's HMD, drawn by MuJoCo's own offscreen renderer: it calibrates on the board as the PyBullet HMD
does, finds the part's marker where MuJoCo has the part, loses it under the cup, and streams the part's position
from a separate process while the MuJoCo cell runs."""

import time
from pathlib import Path

import numpy as np
import pytest

from mrguide.calibration.config import load_calibration_config
from mrguide.calibration.detection import MarkerDetector
from mrguide.cell.config import CellConfig
from mrguide.cell.hmd_stream import (
    MAX_FRAME_RATE,
    OBJECT_MARKER_ID,
    WATCH_EYE,
    WATCH_TARGET,
    HmdPoseStream,
    HmdStartError,
    MujocoDrawing,
)
from mrguide.config import ConfigError, load_section
from mrguide.motion.kinematics import Kinematics
from mrguide.parts import part_named
from mrguide.pose_source import PoseUnavailable
from mrguide.robot import load_robot
from mrguide.twin.camera import Intrinsics
from mrguide.twin.markers import TwinCalibrationConfig, hmd_marker_pose_source

mujoco_hmd = pytest.importorskip("mrguide.cell.mujoco_hmd")  # the mujoco extra (in dev)

MUJOCO_CELL = Path(__file__).parents[2] / "configs" / "cells" / "mujoco_cell.toml"
NO_NOISE = {
    "tracking_noise_m": 0.0,
    "tracking_noise_deg": 0.0,
    "calibration_error_m": 0.0,
    "calibration_error_deg": 0.0,
}


@pytest.fixture(scope="module")
def cell():
    """The MuJoCo cell's HMD calibrated without noise, looking at the cell as the wearer does, and its pose source."""
    env = CellConfig.load(MUJOCO_CELL)
    spec = load_robot(env.robot)
    cfg = load_calibration_config(MUJOCO_CELL)
    twin = load_section(TwinCalibrationConfig, MUJOCO_CELL, "calibration_twin")
    hmd = mujoco_hmd.MujocoHmd(
        spec, env.twin.cup, env.task.object_height, cfg, OBJECT_MARKER_ID, twin.T_base_hmd, twin.intrinsics, 2
    )
    hmd.pose((0.5, -0.05, 0.025), (0, 0, 0, 1), spec.q_home)
    run = mujoco_hmd.calibrate_mujoco_hmd(hmd, cfg, twin.views, twin.look_at)
    hmd.look_from(WATCH_EYE, WATCH_TARGET)
    hmd.supersample = 1
    source = hmd_marker_pose_source(
        hmd, run.record.T_base_hmd, cfg.detector, OBJECT_MARKER_ID, -hmd.T_part_marker[:3, 3]
    )
    yield spec, cfg, twin, hmd, run, source
    hmd.close()


def test_the_board_drawn_by_mujoco_registers_the_hmd_to_a_tenth_of_a_millimetre(cell):
    _, _, twin, _, run, _ = cell
    assert run.record.rms_residual_m < 1e-4
    assert np.linalg.norm(run.record.T_base_hmd[:3, 3] - twin.T_base_hmd[:3, 3]) < 1e-4


@pytest.mark.parametrize(
    ("xy", "yaw_deg"), [((0.5, -0.05), 0.0), ((0.42, 0.05), 30.0), ((0.6, -0.15), -50.0), ((0.38, -0.2), 90.0)]
)
def test_the_part_is_found_where_mujoco_has_it(cell, xy, yaw_deg):
    spec, _, _, hmd, _, source = cell
    half = np.radians(yaw_deg) / 2
    true = np.array([*xy, 0.025])
    hmd.pose(true, (0.0, 0.0, np.sin(half), np.cos(half)), spec.q_home)
    assert np.linalg.norm(source.object_position() - true) < 1e-3


def test_the_cup_on_the_part_hides_its_marker(cell):
    spec, _, _, hmd, _, source = cell
    part = np.array([0.5, -0.05, 0.025])
    q = Kinematics(spec).ik(part + (0.0, 0.0, 0.026), spec.q_home)  # the cup pressed on the top face
    hmd.pose(part, (0, 0, 0, 1), q)
    with pytest.raises(PoseUnavailable):
        source.object_position()
    hmd.pose(part, (0, 0, 0, 1), spec.q_home)
    assert np.linalg.norm(source.object_position() - part) < 1e-3


def test_the_calibration_targets_are_drawn_only_while_calibrating(cell):
    _, cfg, twin, hmd, _, _ = cell
    detector = MarkerDetector(cfg.detector)
    hmd.look_from(twin.views[0], twin.look_at)
    try:
        assert set(detector.detect(hmd.render()).ids) == {OBJECT_MARKER_ID}  # the part's marker, no board
        hmd.show_targets(True)
        assert len(detector.detect(hmd.render()).ids) > 10
    finally:
        hmd.show_targets(False)
        hmd.look_from(WATCH_EYE, WATCH_TARGET)


def test_intrinsics_mujoco_cannot_draw_are_refused(cell):
    spec, cfg, twin, _, _, _ = cell
    off_centre = Intrinsics(width=640, height=480, fx=600.0, fy=600.0, cx=300.0, cy=240.0)
    with pytest.raises(ConfigError, match="centred pinhole"):
        mujoco_hmd.MujocoHmd(spec, CellConfig.load(MUJOCO_CELL).twin.cup, 0.05, cfg, 0, twin.T_base_hmd, off_centre)


def test_the_hmd_process_streams_the_mujoco_cells_part():
    """The HMD of condition mujoco_hmd end to end: its own process, MuJoCo's renderer, the MuJoCo plant's state."""
    from mrguide.mujoco_cell.plant import MujocoPlant

    env = CellConfig.load(MUJOCO_CELL)
    spec = load_robot(env.robot)
    plant = MujocoPlant(spec, env.plant.mujoco, part_named(env.task.part), cup=env.twin.cup)
    part = np.array([0.45, 0.02, 0.025])
    plant.place_objects(part, np.array([0.55, 0.2, 0.025]))
    drawing = MujocoDrawing(spec, env.twin.cup)
    stream = HmdPoseStream(plant, MUJOCO_CELL, env.task.object_height, drawing, hmd_overrides=NO_NOISE)
    try:
        assert stream.calibration["T_base_hmd_translation_error_m"] < 1e-3
        stream.wait_fresh(timeout=60.0)
        assert np.linalg.norm(stream.object_position() - plant.object_position()) < 2e-3
        t0, frames0 = time.monotonic(), stream.frames
        time.sleep(1.0)
        # paced: never more frames than MAX_FRAME_RATE allows (MuJoCo alone would draw more); fewer on a busy machine
        assert stream.frames - frames0 <= MAX_FRAME_RATE * (time.monotonic() - t0) + 1
    finally:
        stream.close()


def test_without_an_offscreen_backend_the_hmd_says_what_to_install(monkeypatch):
    """mujoco picks its OpenGL backend when it is imported: a backend it cannot load stops the HMD at start-up with
    the packages to install, instead of a traceback from inside OpenGL."""
    monkeypatch.setenv("MUJOCO_GL", "no-such-backend")  # the HMD process inherits it (an explicit choice is kept)
    env = CellConfig.load(MUJOCO_CELL)
    spec = load_robot(env.robot)
    with pytest.raises(HmdStartError, match="libegl1 libegl-mesa0 libgl1-mesa-dri"):
        HmdPoseStream(None, MUJOCO_CELL, env.task.object_height, MujocoDrawing(spec, env.twin.cup))
