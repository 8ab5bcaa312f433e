"""A dry run's simulated cell in a process of its own: the deploy stack drives it over the pipe link, reads the
part's pose and feeds parts through the cell process, and the cell outlives a Ctrl-C meant for deploy."""

from __future__ import annotations

import multiprocessing
import os
import signal
import time

import numpy as np
import pytest

from mrguide.cell.cell_process import CellProcessError, cell_process
from mrguide.cell.config import CellConfig
from mrguide.cell.dry_run import dry_run_cycles
from mrguide.deploy.cycles import CycleConfig, CycleRun
from mrguide.deploy.runlog import RunLog, read_log
from tests.deploy.conftest import Expert, bus_config


def test_production_cycles_run_against_a_cell_in_its_own_process(tmp_path):
    cfg = CellConfig()
    cells = []

    def pose_factory(cell):
        from mrguide.cell.twin_plant import TwinObjectPose

        cells.append(cell)
        return TwinObjectPose(cell.plant)

    resting = []  # where each placed part came to rest, read from the cell's process after its cycle

    def after_cycle(report):
        resting.append(cells[0].plant.object_position())

    log = tmp_path / "own.jsonl"
    with RunLog(log, {"test": "own process"}) as run_log:
        summary = dry_run_cycles(
            None,
            cfg,
            bus_config(),
            CycleRun(0, 2, seed=1, config=CycleConfig(), after_cycle=after_cycle),
            run_log,
            pose_factory=pose_factory,
            policy=Expert(cfg),
            own_process=True,
        )
    assert summary.stopped is None and summary.placed == 2, summary.text()
    (cell,) = cells
    assert cell.sim is None and cell.scene is None  # the devices and the physics ran in the other process
    goals = [r["goal"] for r in read_log(log) if r["kind"] == "episode_start"]
    assert len(goals) == 2 and len(resting) == 2
    # each cycle's score says how far the cell's world ran behind the wall clock (read from the cell's process)
    backlogs = [r["cell_backlog_s"] for r in read_log(log) if r["kind"] == "scored"]
    assert len(backlogs) == 2 and all(b >= 0.0 for b in backlogs)
    for goal, rest in zip(goals, resting, strict=True):
        assert np.linalg.norm(np.asarray(goal)[:2] - rest[:2]) < 0.02


def test_the_cell_process_ignores_ctrl_c_and_ends_with_the_block():
    cfg = CellConfig()
    with cell_process(cfg, bus_config(), seed=0) as (plant, master_cfg):
        assert master_cfg.bus.interface == "mrguide_pipe"
        pid = plant.pid
        os.kill(pid, signal.SIGINT)  # what a terminal's Ctrl-C sends to every process of the group
        plant.place_objects(np.array([0.5, 0.0, 0.025]), np.array([0.6, 0.15, 0.025]))
        assert np.allclose(plant.object_position()[:2], [0.5, 0.0], atol=1e-3)
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


def test_a_cell_that_cannot_start_is_reported_with_the_reason():
    cfg = CellConfig().with_value("robot.file", "/no/such/arm.toml", "test")
    with (
        pytest.raises(CellProcessError, match="arm file not found: /no/such/arm"),
        cell_process(cfg, bus_config(), seed=0),
    ):
        pass


def _hold_a_cell(ready) -> None:
    """A deploy process that starts a cell, reports the cell's PID and waits to be killed."""
    with cell_process(CellConfig(), bus_config(), seed=0) as (plant, _cfg):
        ready.send(plant.pid)
        time.sleep(600)


def test_a_killed_deploy_process_leaves_no_cell_behind():
    ctx = multiprocessing.get_context("spawn")
    ours, theirs = ctx.Pipe()
    deploy = ctx.Process(target=_hold_a_cell, args=(theirs,))
    deploy.start()
    assert ours.poll(120), "the cell did not start"
    cell_pid = ours.recv()
    deploy.kill()  # SIGKILL: no cleanup in the deploy process
    deploy.join()
    for _ in range(200):
        try:
            os.kill(cell_pid, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        os.kill(cell_pid, signal.SIGKILL)
        pytest.fail("the cell's process outlived the deploy process by 10 s")


def test_the_link_is_drained_while_the_cell_starts_so_its_devices_never_block():
    """The devices boot and talk in the cell's constructor, before the master reads the link: undrained, the link's
    end fills after a few hundred frames and the sender blocks (a hung dry run on a slow machine)."""
    from mrguide.cell.cell_process import _drained
    from mrguide.drivers.mock.pipe_bus import pipe_link

    master_end, device_end = pipe_link()
    device_end.settimeout(60.0)  # a blocked send fails the test instead of hanging it
    try:
        with _drained(master_end):
            for _ in range(5000):
                device_end.send(bytes(16))
        assert master_end.gettimeout() is None  # the master's bus reads a blocking end again
    finally:
        master_end.close()
        device_end.close()
