"""Shared pieces for the deploy tests: the scripted expert as a policy and a dry-run helper."""

import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from mrguide.cell.config import CellConfig
from mrguide.cell.dry_run import dry_run
from mrguide.deploy.runlog import RunLog
from mrguide.drivers.config import BusConfig, CobotBusConfig
from mrguide.robot import load_robot
from mrguide.task import oracle_action, phase_from_progress
from mrguide.twin.env import EnvConfig

_channels = itertools.count()


def bus_config() -> CobotBusConfig:
    """Default bus description on a virtual channel of its own (tests never share a bus)."""
    return CobotBusConfig(bus=BusConfig(interface="virtual", channel=f"deploy-test-{next(_channels)}"))


class Expert:
    """The scripted expert as a deploy policy; `hook(obs, phase)` may inject faults or misbehave."""

    def __init__(self, cfg: EnvConfig | CellConfig, hook=None):
        self.cfg, self.hook = cfg, hook
        self.ws = load_robot(cfg.robot).workspace

    def __call__(self, obs):
        a = oracle_action(obs, self.cfg.task, self.ws.to_normalized)
        if self.hook:
            a = self.hook(obs, phase_from_progress(obs[4]), a)
        return np.asarray(a, dtype=np.float32)


@pytest.fixture()
def run_dry(tmp_path):
    """dry_run with the expert; returns (summary, run log path, the cell the run used).

    `pose(cell)` may give the object pose source (default: the exact pose from the twin), `on_placed` runs
    after the object was placed; `runtime_cfg` sets the runtime (RuntimeConfig); `own_process` runs the cell in a
    process of its own, as `mrguide deploy --dry-run` does (a hook then has no simulated devices to reach)."""

    def run(
        episodes=1,
        seed=0,
        hook=None,
        env_cfg=None,
        safety=None,
        on_cell=None,
        max_recoveries=0,
        pose=None,
        runtime_cfg=None,
        on_placed=None,
        own_process=False,
    ):
        cfg = env_cfg if isinstance(env_cfg, CellConfig) else CellConfig(env=env_cfg or EnvConfig())  # a cell of an env
        cells = []

        def pose_factory(cell):
            from mrguide.cell.twin_plant import TwinObjectPose

            cells.append(cell)
            if on_cell:
                on_cell(cell)
            return pose(cell) if pose else TwinObjectPose(cell.plant)

        log = tmp_path / f"run-{seed}.jsonl"
        with RunLog(log, {"test": "dry run"}) as run_log:
            summary = dry_run(
                None,
                cfg,
                bus_config(),
                episodes,
                seed,
                run_log,
                safety,
                pose_factory=pose_factory,
                policy=Expert(cfg, (lambda o, p, a: hook(o, p, a, cells[0])) if hook else None),
                max_recoveries=max_recoveries,
                runtime_cfg=runtime_cfg,
                on_placed=on_placed,
                own_process=own_process,
            )
        return summary, log, cells[0]

    return run


@dataclass(frozen=True)
class CameraScene:
    """Twin-rendered 1280x720 images of the marked cube from a fixed camera, with the ground truth."""

    folder: Path  # the images, one per object position, in name order
    truths: list[np.ndarray]  # object centres (base frame, m)
    calibration: Path  # the camera's calibration file (ground-truth registration and intrinsics)
    T_base_cam: np.ndarray


#: A fixed camera ~0.75 m from the object region, looking down at it.
CAMERA_EYE, CAMERA_TARGET = (1.0, -0.05, 0.55), (0.5, -0.05, 0.0)


@pytest.fixture(scope="session")
def camera_scene(tmp_path_factory) -> CameraScene:
    import cv2
    import pybullet as pb

    from mrguide.calibration.calibration_file import CalibrationRecord, save_calibration
    from mrguide.calibration.camera_model import CameraModel
    from mrguide.cell.camera_feed import render_marked_object
    from mrguide.twin.camera import look_at
    from mrguide.twin.markers import HOLOLENS2_PV

    d = tmp_path_factory.mktemp("camera")
    T = look_at(np.array(CAMERA_EYE), np.array(CAMERA_TARGET), np.array([0.0, 0.0, 1.0]))
    cam = CameraModel.from_pinhole(HOLOLENS2_PV)
    calibration = save_calibration(
        CalibrationRecord(T, "DICT_4X4_50", 0.04, "board", 0.001, 0.002, 1, 80, camera=cam.to_dict()),
        d / "calibration.json",
    )
    truths = [np.array([0.45, -0.12, 0.025]), np.array([0.58, -0.02, 0.025]), np.array([0.50, -0.07, 0.025])]
    yaws = [0.3, -1.2, 2.5]
    images = render_marked_object(
        T, cam, [(p, pb.getQuaternionFromEuler([0, 0, y])) for p, y in zip(truths, yaws)], 0.05, "DICT_4X4_50", 0, 0.04
    )
    (d / "images").mkdir()
    for i, image in enumerate(images):
        cv2.imwrite(str(d / "images" / f"frame{i:02d}.png"), cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    return CameraScene(d / "images", truths, calibration, T)
