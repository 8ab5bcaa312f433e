"""Deploy with the `camera` pose source: dry runs whose frames the twin renders (the real camera code path),
a camera that dies mid-episode, `mrguide camera check` on a folder, and bad [deploy.camera] values."""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.cell.camera_feed import TwinCameraFeed, TwinCameraPoses
from mrguide.deploy.camera import CameraSourceConfig
from mrguide.deploy.runlog import read_log
from mrguide.deploy.runtime_config import RuntimeConfig
from mrguide.robot import load_robot
from mrguide.task import Outcome
from mrguide.twin.visual_arm import ArmDrawing

#: No test here is about a pose's age: the twin renders every frame on the CPU, which a busy machine slows to
#: seconds (the age limit itself: tests/deploy/test_camera_source.py, and its bad values below).
AGE = 30.0


def _poses(scene, **changes) -> TwinCameraPoses:
    cfg = CameraSourceConfig(**{"calibration": str(scene.calibration), "max_pose_age_s": AGE, **changes})
    return TwinCameraPoses(cfg, scene.calibration.parent, 0.05, ArmDrawing.of(load_robot()))


def test_dry_run_with_the_camera_source_places_the_object(run_dry, camera_scene):
    poses = _poses(camera_scene)
    try:
        summary, _log, _cell = run_dry(episodes=1, seed=1, pose=poses, on_placed=poses.refresh)
        stats = poses.stats()
    finally:
        poses.close()
    assert summary.stopped is None and summary.successes == 1, summary.text()
    # at least the pose the episode waited for after placing the part; how many more the renderer delivers depends on
    # how fast the machine renders, and the arm hides the marker while it reaches for the part
    assert stats.poses >= 1 and stats.lost is None, stats
    assert not summary.events().get("pose_lost")


def test_the_arm_over_the_part_hides_its_marker_from_the_camera(camera_scene):
    """The render process draws the arm: with the cup 2 cm above the part, between it and the camera, the marker
    is not found; with the arm at home it is, within 2 mm."""
    from mrguide.calibration.hmd import HmdFrame
    from mrguide.deploy.camera import load_marker_pipeline
    from mrguide.motion.kinematics import Kinematics

    spec = load_robot()
    cfg = CameraSourceConfig(calibration=str(camera_scene.calibration))
    pipeline = load_marker_pipeline(cfg, camera_scene.calibration.parent)
    feed = TwinCameraFeed(pipeline.T_base_hmd, pipeline.camera, 0.05, "DICT_4X4_50", 0, 0.04, ArmDrawing.of(spec))
    part = np.array([0.50, -0.07, 0.025])
    over = Kinematics(spec).ik(part + [0.0, 0.0, 0.045], spec.q_home)  # cup lip 2 cm above the part's top
    try:
        seen = {}
        for name, q in (("home", spec.q_home), ("over", over)):
            feed.view = lambda q=q: (part, np.array([0.0, 0.0, 0.0, 1.0]), q)
            seen[name] = pipeline.observe(HmdFrame(feed.read().image, np.eye(4)))
    finally:
        feed.close()
    assert seen["home"].position is not None and np.linalg.norm(seen["home"].position - part) < 0.002
    assert seen["over"].position is None and "not visible" in seen["over"].problem


def test_camera_dying_mid_episode_ends_it_pose_lost_with_the_log_intact(run_dry, camera_scene):
    poses = _poses(camera_scene)
    killed = []

    def kill_camera(obs, phase, action, cell):
        if not killed:
            source = poses.sources[0]
            lose = source._lose

            def lose_and_go_stale(reason: str) -> None:  # once the source knows, the last pose is stale
                lose(reason)
                source.max_age = 0.01

            source._lose = lose_and_go_stale
            source.frames.read = lambda: None  # the device stops delivering frames
            # what the capture thread finds at its next read: not whenever a busy machine's renderer finishes the frame
            # the thread is waiting for now, which may come after the episode has ended
            lose_and_go_stale("the camera source has no more frames")
            killed.append(True)
        return action

    try:
        summary, log, _ = run_dry(
            episodes=1,
            seed=1,
            pose=poses,
            on_placed=poses.refresh,
            hook=kill_camera,
            runtime_cfg=RuntimeConfig(track_carried_object=False, max_pose_misses=2, max_pose_misses_before_grasp=2),
        )
        stats = poses.stats()
    finally:
        poses.close()
    assert summary.stopped is None
    assert summary.outcomes() == {Outcome.POSE_LOST.value: 1}, summary.text()
    assert summary.events()["pose_unavailable"] == 2 and summary.events()["pose_lost"] == 1
    assert stats.lost == "the camera source has no more frames"
    records = read_log(log)
    end = [r for r in records if r["kind"] == "episode_end"]
    assert len(end) == 1 and end[0]["outcome"] == "pose_lost"
    lost = [r for r in records if r["kind"] == "safety" and r["event"] == "pose_lost"]
    assert lost and "no more frames" in lost[0]["detail"]


@pytest.fixture
def camera_cfg(tmp_path, camera_scene):
    """cfg(deploy_extra, camera_extra) -> path of a config with the camera source and a virtual bus of its own."""
    (tmp_path / "bus.toml").write_text(f'[bus]\nchannel = "camera-deploy-{tmp_path.name}"\n')

    def write(deploy='pose_source = "camera"', camera="", extra="") -> object:
        path = tmp_path / "cfg.toml"
        path.write_text(
            f'[deploy]\nbus_config = "bus.toml"\n{deploy}\n[deploy.camera]\n'
            f'calibration = "{camera_scene.calibration}"\nsource = "{camera_scene.folder}"\n{camera}\n{extra}'
        )
        return path

    return write


def test_cli_dry_run_with_the_camera_source(tmp_path, camera_cfg, run_cli, policy_file):
    from mrguide.config import to_dict
    from mrguide.task import TaskConfig

    policy = policy_file(tmp_path / "p.npz", task=to_dict(TaskConfig(horizon=5)))
    log = tmp_path / "log.jsonl"
    result = run_cli(
        [
            "deploy",
            "--policy",
            policy,
            "--config",
            camera_cfg(camera=f"max_pose_age_s = {AGE}", extra="[task]\nhorizon = 5\n"),
            "--dry-run",
            "--episodes",
            1,
            "--log",
            log,
            "--quiet",
        ]
    )
    assert result.code == 0, result.err
    assert "episodes: 1" in result.out and "camera: " in result.out and "detected" in result.out
    records = read_log(log)
    assert records[0]["pose_source"] == "camera"
    assert sum(r["kind"] == "decision" and "setpoints" in r for r in records) == 5
    camera = [r for r in records if r["kind"] == "camera"]
    assert len(camera) == 1 and camera[0]["poses"] >= 1


def test_camera_check_on_a_folder_prints_the_rate_and_writes_the_overlay(tmp_path, camera_cfg, run_cli, camera_scene):
    import cv2

    overlay = tmp_path / "check.png"
    result = run_cli(
        ["camera", "check", "--config", camera_cfg(camera="frame_rate = 0.0"), "--frames", 3, "--overlay", overlay]
    )
    assert result.code == 0, result.err
    assert "3 frames, 3 poses (100% detected)" in result.out and "latency median" in result.out, result.out
    assert "object (marker 0) in the robot frame:" in result.out
    shown = np.array(result.out.split("robot frame: ")[1].split(" m")[0].strip("[]").split(","), dtype=float)
    assert np.linalg.norm(shown - camera_scene.truths[-1]) < 0.002
    image = cv2.imread(str(overlay))
    assert image is not None and image.shape == (720, 1280, 3)


BAD = [
    # (id, [deploy] lines, [deploy.camera] lines, words in the one stderr line)
    (
        "pose_source lidar",
        'pose_source = "lidar"',
        "",
        ["[deploy]", "deploy.pose_source = 'lidar'", "fixed, camera, hmd"],
    ),
    ("max age 0", 'pose_source = "camera"', "max_pose_age_s = 0", ["deploy.camera.max_pose_age_s = 0"]),
    ("max age nan", 'pose_source = "camera"', "max_pose_age_s = nan", ["camera.max_pose_age_s = nan"]),
    ("source true", 'pose_source = "camera"', "source = true", ["deploy.camera.source = True"]),
    ("source -1", 'pose_source = "camera"', "source = -1", ["deploy.camera.source = -1"]),
    ("unknown key", 'pose_source = "camera"', "fps = 30", ["[deploy]", "fps"]),
    ("marker size 0", 'pose_source = "camera"', "marker_size_m = 0.0", ["deploy.camera.marker_size_m = 0.0"]),
    (
        "calibration missing",
        'pose_source = "camera"',
        'calibration = "nope.json"',
        ["calibration file not found", "nope.json"],
    ),
]


@pytest.mark.parametrize("deploy, camera, words", [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_bad_camera_config_is_refused_in_one_line(tmp_path, camera_cfg, run_cli, policy_file, deploy, camera, words):
    path = camera_cfg(deploy, camera)
    text = path.read_text()
    if camera.startswith("calibration") or camera.startswith("source"):  # the later key would be a duplicate
        key = camera.split(" =")[0]
        text = "\n".join(line for line in text.splitlines() if not line.startswith(key + ' = "/')) + "\n"
        path.write_text(text)
    log = tmp_path / "log.jsonl"
    run_cli(
        [
            "deploy",
            "--policy",
            policy_file(tmp_path / "p.npz"),
            "--config",
            path,
            "--dry-run",
            "--episodes",
            1,
            "--log",
            log,
            "--quiet",
        ]
    ).assert_refused(*words)
    assert not log.exists()
    run_cli(["camera", "check", "--config", path, "--frames", 1, "--overlay", tmp_path / "o.png"]).assert_refused(
        *words
    )


def test_camera_check_refuses_an_empty_folder_and_an_overlay_it_cannot_write(tmp_path, camera_cfg, run_cli):
    (tmp_path / "empty").mkdir()
    path = camera_cfg()
    path.write_text(path.read_text().replace("\nsource = ", '\nsource = "empty"\n# '))
    run_cli(["camera", "check", "--config", path, "--overlay", tmp_path / "o.png"]).assert_refused(
        "camera check", "the folder holds no images"
    )
    run_cli(["camera", "check", "--config", path, "--overlay", tmp_path / "o.xyz"]).assert_refused("--overlay", ".xyz")


def test_the_example_camera_config_loads():
    from pathlib import Path

    from mrguide.config import load_section
    from mrguide.deploy.camera import load_marker_pipeline
    from mrguide.deploy.session import DeployConfig

    path = Path(__file__).parents[2] / "configs" / "cells" / "camera_cell.toml"
    cfg = load_section(DeployConfig, path, "deploy")
    assert cfg.pose_source == "camera" and cfg.camera.source == 0
    pipeline = load_marker_pipeline(cfg.camera, path.parent)
    assert (pipeline.camera.width, pipeline.camera.height) == (1280, 720)
