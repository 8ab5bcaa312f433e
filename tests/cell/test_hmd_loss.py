"""A dead HMD pose process fails closed: the runtime uses the last pose for a few decisions, then stops the
episode cleanly (counted and logged), and the run ends with a reason instead of a traceback or going on."""

import multiprocessing as mp
import time
from pathlib import Path

import numpy as np
import pytest

from mrguide.cell.config import CellConfig
from mrguide.cell.hmd_stream import HmdPoseStream
from mrguide.cell.twin_plant import TwinPlant
from mrguide.deploy.runlog import read_log
from mrguide.deploy.runtime_config import RuntimeConfig
from mrguide.deploy.safety import SafetyConfig
from mrguide.drivers.config import BusConfig, CobotBusConfig
from mrguide.experiments import sim2real as s2r
from mrguide.parts import part_named
from mrguide.pose_source import PoseUnavailable
from mrguide.robot import load_robot
from mrguide.task import oracle_action, phase_from_progress
from mrguide.twin.scene import Scene
from mrguide.twin.visual_arm import ArmDrawing

REAL = Path(__file__).parents[2] / "configs" / "cells" / "real_cell.toml"
HMD_ERRORS = ("tracking_noise_m", "tracking_noise_deg", "calibration_error_m", "calibration_error_deg")


def _kill_hmd(wait: bool = True) -> int:
    """SIGKILL the HMD pose process; with `wait`, also reap it (not from inside a decision: on a busy machine the
    wait alone can outlast the stall watchdog)."""
    killed = 0
    for child in mp.active_children():
        if child.name == "hmd":
            child.kill()
            if wait:
                child.join(5)
            killed += 1
    return killed


def test_dead_hmd_process_is_unavailable_at_once():
    cfg = CellConfig.load(REAL)
    scene = Scene(load_robot(cfg.robot), cfg.twin, part_named(cfg.task.part))
    stream = HmdPoseStream(TwinPlant(scene), REAL, cfg.task.object_height, ArmDrawing.of(scene.spec))
    try:
        stream.wait_fresh()
        assert np.linalg.norm(stream.object_position() - scene.object_position()) < 0.02
        assert _kill_hmd() == 1
        t0 = time.monotonic()
        with pytest.raises(PoseUnavailable, match="HMD process"):
            stream.object_position()  # not only once the last estimate is max_age (3 s) old
        stream.invalidate()
        with pytest.raises(PoseUnavailable, match="HMD process"):
            stream.wait_fresh(timeout=10.0)  # not after waiting the 10 s out
        assert time.monotonic() - t0 < 1.0
    finally:
        stream.close()
        scene.close()


def test_a_dead_hmd_process_is_gone_even_while_is_alive_has_not_caught_up(monkeypatch):
    """A child reaped by another thread can read as alive for a moment (its exit code not yet stored): the
    stream judges by the process's sentinel, so the last pose is refused at once all the same."""
    cfg = CellConfig.load(REAL)
    scene = Scene(load_robot(cfg.robot), cfg.twin, part_named(cfg.task.part))
    stream = HmdPoseStream(TwinPlant(scene), REAL, cfg.task.object_height, ArmDrawing.of(scene.spec))
    try:
        stream.wait_fresh()
        stream._stop.set()  # the reader thread ends without noticing anything, so only the process check is left
        stream._thread.join(timeout=10)
        assert _kill_hmd() == 1
        monkeypatch.setattr(stream._proc, "is_alive", lambda: True)
        with pytest.raises(PoseUnavailable, match="HMD process is not running"):
            stream.object_position()
    finally:
        stream.close()
        scene.close()


def test_hmd_dying_in_the_grasp_finishes_the_episode_on_the_last_pose_then_stops_the_run(tmp_path):
    """Before the grasp the part lies where it was last seen, so the last pose serves (up to
    `max_pose_misses_before_grasp` decisions, each counted); from the grasp on the carried part is tracked by the
    TCP. The next episode cannot start without a pose: the run stops, naming the HMD process.

    The HMD sees without the real cell's errors here: its death is what is tested, not its accuracy. With them the
    last pose can lie beyond the cup's 5 mm seal margin (`mrguide.seal`), and whether the runtime's seal search then
    finds the seal within the last pose's allowance depends on the draw."""
    cfg = CellConfig.load(REAL)
    ws = load_robot(cfg.robot).workspace
    killed = []

    def expert_then_kill(obs):
        if phase_from_progress(obs[4]) == 1 and not killed:
            killed.append(_kill_hmd(wait=False))
        return oracle_action(obs, cfg.task, ws.to_normalized)

    log = tmp_path / "log.jsonl"
    out = s2r.run_real(
        None,
        cfg,
        CobotBusConfig(bus=BusConfig(channel="s2r-hmd-loss")),
        seed=0,
        episodes=2,
        log_path=log,
        hmd_config=REAL,
        # the stall watchdog is tested elsewhere: here a busy machine's pause must not end the first episode
        safety=SafetyConfig(stall_timeout=2.0),
        policy=expert_then_kill,
        use_hmd=True,
        hmd_overrides=dict.fromkeys(HMD_ERRORS, 0.0),
    )
    assert killed == [1]
    assert out == ["success", "safety_stop"]  # the second episode could not start
    records = read_log(log)
    safety = [(r["event"], r["reaction"]) for r in records if r["kind"] == "safety" and r["event"] != "break_away"]
    assert 1 <= len(safety) <= RuntimeConfig().max_pose_misses_before_grasp  # besides the lift rule's break-away
    assert set(safety) == {("pose_unavailable", "last_known")}, safety
    ends = [r for r in records if r["kind"] == "episode_end"]
    assert [e["outcome"] for e in ends] == ["success"]
    stopped = [r for r in records if r["kind"] == "run_stopped"]
    assert len(stopped) == 1 and "no object pose" in stopped[0]["reason"] and "HMD process" in stopped[0]["reason"]


def test_an_hmd_that_cannot_start_fails_its_seed_and_the_run_goes_on(tmp_path, monkeypatch):
    """With too much head-tracking noise the HMD's marker calibration fails (2 cm: the 4 views disagree by ~2 cm):
    that seed's episodes count as safety stops, the log says why, and nothing raises (a sweep goes on)."""

    def cannot_start(*args, **kwargs):
        raise s2r.HmdStartError("HMD process failed to start: CalibrationError: registration: only 0 of 4 frames agree")

    monkeypatch.setattr(s2r, "HmdPoseStream", cannot_start)
    cfg = CellConfig.load(REAL)
    seen = []
    log = tmp_path / "log.jsonl"
    out = s2r.run_real(
        None,
        cfg,
        CobotBusConfig(bus=BusConfig(channel="s2r-hmd-start")),
        seed=1,
        episodes=3,
        log_path=log,
        hmd_config=REAL,
        safety=None,
        on_episode=seen.append,
        use_hmd=True,
        hmd_overrides={"tracking_noise_m": 0.02},
    )
    assert out == seen == ["safety_stop"] * 3
    records = read_log(log)
    assert records[0]["hmd_overrides"] == {"tracking_noise_m": 0.02}
    assert records[-1]["kind"] == "run_stopped" and "the HMD could not start" in records[-1]["reason"]


def test_the_hmd_process_ends_quietly_when_its_parent_is_gone():
    """A parent killed mid-run (its end of the pipe closed) ends the HMD process's answer loop without a traceback,
    whether it was waiting for a request or answering one."""
    from mrguide.cell.hmd_stream import _answer_poses

    class Blind:
        def object_position(self) -> np.ndarray:
            raise PoseUnavailable("marker 0 not visible")

    for last_request in (False, True):
        ours, theirs = mp.Pipe()
        if last_request:
            theirs.send((np.eye(4),))  # a request, then the parent dies before the answer is read
        theirs.close()
        _answer_poses(ours, lambda *_: None, Blind())  # returns: no EOFError, no BrokenPipeError
