"""One plant contract behind the simulated bus, on both physics engines: the PyBullet twin and the MuJoCo cell.

Each test boots the simulated drives and vacuum generator around the engine's plant, connects the master and
checks what a cell must do over CANopen: enable and hold home, jog a joint to where it was sent, seal on a part
and report it, lose the vacuum to a leak, release, and quick-stop mid-move. A scripted pick-and-place over the
bus must place the part in the MuJoCo cell.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import replace

import numpy as np
import pytest

from mrguide.cell.config import CellConfig
from mrguide.cell.plants import PLANT_BUILDERS
from mrguide.drivers import Cobot
from mrguide.drivers.mock import SimulatedCobot
from mrguide.drivers.mock.sim_cobot import shared_pc_config
from mrguide.drivers.realtime import settled_heap
from mrguide.motion.kinematics import Kinematics
from mrguide.motion.trajectory import point_to_point

PART = np.array([0.50, -0.10, 0.025])  # on the table, in reach
GOAL = np.array([0.45, 0.20, 0.025])


@pytest.fixture(params=sorted(PLANT_BUILDERS))
def cell(request, make_config, robot) -> Iterator[tuple]:
    """(config, plant, simulated devices, enabled master) around each registered engine's plant, the part placed. The
    bus timing is a dry run's (`shared_pc_config`): the plant steps in the devices' thread, in the master's process."""
    config = shared_pc_config(make_config())
    env_cfg = CellConfig()
    twin_cfg = replace(env_cfg.twin, control_period=config.timing.control_period, gui=False)
    plant, scene = PLANT_BUILDERS[request.param](env_cfg, twin_cfg, robot, 0)
    plant.place_objects(PART, GOAL)
    with settled_heap():
        sim = SimulatedCobot(config, plant)
        sim.start()
        cobot = Cobot(config, robot)
        try:
            cobot.connect()
            cobot.enable()
            yield config, plant, sim, cobot
        finally:
            cobot.disconnect()
            sim.stop()
            if scene is not None:
                scene.close()


def _move(cobot: Cobot, robot, q_to: np.ndarray, settle_s: float = 0.3) -> None:
    for q in point_to_point(robot, cobot.setpoint, q_to, cobot.period):
        cobot.stream(q)
    for _ in range(round(settle_s / cobot.period)):
        cobot.stream(q_to)


def _move_tcp(cobot: Cobot, robot, kin: Kinematics, target: np.ndarray) -> None:
    _move(cobot, robot, kin.ik(target, cobot.setpoint))


def _wait(predicate, timeout: float = 20.0) -> bool:
    end = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > end:
            return False
        time.sleep(0.004)
    return True


def test_enable_holds_home_and_a_jog_arrives(cell, robot):
    _config, plant, _sim, cobot = cell
    assert all(s == "OPERATION ENABLED" for s in cobot.status().drive_states.values())
    assert np.abs(cobot.joint_state().positions - robot.q_home).max() < 2e-3
    target = robot.q_home + np.array([0.2, -0.1, 0.1, 0.0, 0.0, 0.3])
    _move(cobot, robot, target)
    assert np.abs(plant.joint_positions() - target).max() < 2e-3  # the engine's joints, not only the feedback
    assert np.abs(cobot.joint_state().positions - target).max() < 2e-3


def test_vacuum_seals_on_the_part_leaks_and_releases(cell, robot):
    config, plant, sim, cobot = cell
    kin = Kinematics(robot)
    cobot.set_vacuum(True)  # open air: some vacuum, no part
    assert _wait(lambda: cobot.vacuum_state().level_kpa > 3.0)
    time.sleep(0.2)
    assert not cobot.vacuum_state().part_gripped and cobot.vacuum_state().level_kpa < config.vacuum.grip_threshold_kpa
    _move_tcp(cobot, robot, kin, PART + [0.0, 0.0, 0.10])
    _move_tcp(cobot, robot, kin, PART + [0.0, 0.0, 0.025])  # the lip on the part's top face
    assert _wait(lambda: cobot.vacuum_state().part_gripped), cobot.vacuum_state()
    assert plant.part_present()
    sim.set_vacuum_leak(1.0)  # the line leaks: the level falls below L1 - h1 with the vacuum on
    assert _wait(lambda: cobot.vacuum_state().part_lost), cobot.vacuum_state()
    sim.set_vacuum_leak(0.0)
    assert _wait(lambda: cobot.vacuum_state().part_gripped)
    cobot.set_vacuum(False, blow_off=True)
    assert _wait(lambda: cobot.vacuum_state().level_kpa < 1.0)
    assert not cobot.vacuum_state().part_gripped


def test_quick_stop_mid_move_brings_the_arm_to_rest(cell, robot):
    _config, plant, _sim, cobot = cell
    path = point_to_point(robot, cobot.setpoint, robot.q_home + np.array([1.0, 0, 0, 0, 0, 0]), cobot.period)
    for q in path[: len(path) // 2]:
        cobot.stream(q)
    cobot.stop()
    assert _wait(lambda: all(s != "OPERATION ENABLED" for s in cobot.status().drive_states.values()))
    assert _wait(lambda: np.abs(plant.joint_velocities()).max() < 1e-2)
    stopped = plant.joint_positions()
    time.sleep(0.2)
    assert np.abs(plant.joint_positions() - stopped).max() < 2e-3  # held where it stopped
    assert abs(stopped[0] - robot.q_home[0]) < 1.0  # stopped short of the target


def test_a_scripted_pick_and_place_over_the_bus_places_the_part(cell, robot):
    _config, plant, _sim, cobot = cell
    kin = Kinematics(robot)
    _move_tcp(cobot, robot, kin, PART + [0.0, 0.0, 0.10])
    _move_tcp(cobot, robot, kin, PART + [0.0, 0.0, 0.025])
    cobot.set_vacuum(True)
    assert _wait(lambda: cobot.vacuum_state().part_gripped)
    _move_tcp(cobot, robot, kin, PART + [0.0, 0.0, 0.15])
    assert plant.object_position()[2] > 0.10  # lifted with the cup
    _move_tcp(cobot, robot, kin, GOAL + [0.0, 0.0, 0.15])
    _move_tcp(cobot, robot, kin, GOAL + [0.0, 0.0, 0.027])
    cobot.set_vacuum(False, blow_off=True)
    assert _wait(lambda: not cobot.vacuum_state().part_gripped)
    _move_tcp(cobot, robot, kin, GOAL + [0.0, 0.0, 0.10])
    placed = plant.object_position()
    assert np.linalg.norm(placed[:2] - GOAL[:2]) < 0.01 and abs(placed[2] - GOAL[2]) < 0.003, placed
