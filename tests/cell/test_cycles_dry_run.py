"""Production cycles through the whole stack against the simulated cell: a part lost in the lift is picked again
where it fell, the lift rules of the runtime act on every lift, and a part still on the cup when the horizon runs out
is set down where it was seen; the cycle a safety stop ends says how far the simulated cell ran behind the clock."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mrguide.cell.config import CellConfig
from mrguide.cell.dry_run import dry_run_cycles
from mrguide.cli import main
from mrguide.deploy.cycles import CycleConfig, CycleRun, CycleSummary
from mrguide.deploy.runlog import RunLog, read_log
from mrguide.motion.kinematics import Kinematics
from mrguide.replay.runs import load_run
from mrguide.robot import load_robot
from mrguide.task import OBS_OBJECT, Phase
from tests.deploy.conftest import Expert, bus_config


def in_process(log: Path, cfg: CellConfig, run: CycleRun, hook, cells: list) -> CycleSummary:
    """Cycles of the expert against a cell in the test's process, `hook(obs, phase, action, cell)` on its every
    action (`cells` gets the cell: a hook may reach its simulated devices)."""

    def pose_factory(cell):
        from mrguide.cell.twin_plant import TwinObjectPose

        cells.append(cell)
        return TwinObjectPose(cell.plant)

    with RunLog(log, {"test": log.stem}) as run_log:
        return dry_run_cycles(
            None,
            cfg,
            bus_config(),
            run,
            run_log,
            pose_factory=pose_factory,
            policy=Expert(cfg, lambda o, p, a: hook(o, p, a, cells[0])),
        )


def test_a_part_dropped_in_the_lift_is_picked_again_and_placed(tmp_path):
    cfg = CellConfig()
    leaks = []

    def leak_once(obs, phase, a, cell):
        """The first lift of the run loses its vacuum (a torn seal); the vacuum is whole again after it."""
        if phase == 2 and not leaks:
            cell.sim.set_vacuum_leak(1.0)
            leaks.append(1)
        elif phase == 0 and leaks:
            cell.sim.set_vacuum_leak(0.0)
        return a

    cells: list = []
    kin = Kinematics(load_robot(cfg.robot))
    clearance = []  # after each placed cycle: how far the TCP stands above the top of the part it let go

    def after_cycle(report):
        _pos, _orn, q = cells[0].plant.view()
        part_top = cells[0].plant.object_position()[2] + 0.5 * cfg.task.object_height
        clearance.append(kin.tcp_position(q)[2] - part_top)

    log = tmp_path / "cycles.jsonl"
    summary = in_process(
        log, cfg, CycleRun(0, 2, seed=3, config=CycleConfig(), after_cycle=after_cycle), leak_once, cells
    )
    assert summary.stopped is None, summary.text()
    assert summary.placed == 2 and summary.retries() == {"dropped": 1}, summary.text()
    assert summary.cycles[0].outcomes == ["dropped", "success"]
    assert len(clearance) == 2 and min(clearance) > 0.04, clearance  # each place departed (5 cm) straight up
    records = read_log(log)
    assert [(r["cycle"], r["cause"]) for r in records if r["kind"] == "retry"] == [(0, "dropped")]
    # the lift rules: every lift started slowly (break-away), and each is in the run log
    lifts = [r for r in records if r["kind"] == "decision" and r.get("lift_rule") == "break_away"]
    assert {r["episode"] for r in lifts} == {0, 1, 2}
    (final,) = [r for r in records if r["kind"] == "cycles_end"]
    assert final["placed"] == 2 and final["alarms"] == [] and final["retries"] == {"dropped": 1}
    # `mrguide replay` shows the recovered drop: the dropped attempt ends with the retry, the next one succeeds
    dropped, again, _ = load_run(log)
    assert dropped.outcome == "dropped" and again.outcome == "success"
    assert dropped.events[-1]["event"] == "retry" and "picked again" in dropped.events[-1]["detail"]
    assert main(["replay", f"{log}:0,1", "--save", str(tmp_path / "recovered.rrd")]) == 0
    assert (tmp_path / "recovered.rrd").stat().st_size > 0


def one_cycle(log: Path, cfg: CellConfig, hook):
    """One production cycle of the scripted expert (`hook` may make it misbehave) in the simulated cell, logged; the
    cell in a process of its own, as `mrguide deploy --dry-run` runs it (in the test's process its physics waits for
    the GIL, and on a busy machine fell behind the setpoints into a following-error stop)."""
    with RunLog(log, {"test": log.stem}) as run_log:
        return dry_run_cycles(
            None,
            cfg,
            bus_config(),
            CycleRun(0, 1, seed=3, config=CycleConfig()),
            run_log,
            policy=Expert(cfg, hook),
            own_process=True,
        )


def test_a_release_asked_in_transport_is_refused_and_the_part_placed(tmp_path):
    cfg = CellConfig()
    asked = []

    def release_in_transport(obs, phase, a):
        """A policy that lets go half-way: the third decision of the transport asks the vacuum off."""
        if phase == 3:
            asked.append(1)
            if len(asked) == 3:
                return a * [1, 1, 1, 0] - [0, 0, 0, 1]
        return a

    log = tmp_path / "cycles.jsonl"
    summary = one_cycle(log, cfg, release_in_transport)
    assert len(asked) >= 3, "the transport never got to its third decision"
    assert summary.placed == 1 and summary.retries() == {}, summary.text()
    decisions = [r for r in read_log(log) if r["kind"] == "decision"]
    held = [r for r in decisions if r.get("hold_rule") == "hold_in_transit"]
    assert len(held) == 1 and held[0]["action"][3] == -1.0, held


def test_a_part_held_when_the_horizon_runs_out_is_set_down_where_it_was_seen_and_picked_again(tmp_path):
    cfg = CellConfig()
    ws = load_robot(cfg.robot).workspace
    hovered: list[int] = []
    retried: list[int] = []

    def hover_in_the_first_transport(obs, phase, a):
        """The first attempt's transport stops 15 cm up over the place side, the part held, until the horizon."""
        if phase == Phase.APPROACH and hovered:
            retried.append(1)
        if phase == Phase.TRANSPORT and not retried:
            hovered.append(1)
            return np.array([*ws.to_normalized(np.array([0.5, 0.12, 0.15])), 1.0])
        return a

    log = tmp_path / "cycles.jsonl"
    summary = one_cycle(log, cfg, hover_in_the_first_transport)
    assert summary.cycles[0].outcomes == ["timeout", "success"], summary.text()
    records = read_log(log)
    (down,) = [r for r in records if r["kind"] == "set_down"]
    assert down["done"] and down["tcp"][1] > 0.1 and down["tcp"][2] > 0.1  # carried back from over the place side
    first, again = (r["obs"][OBS_OBJECT] for r in records if r["kind"] == "decision" and r["t"] == 0)
    # the retry found the part where the first attempt had, in the pick region (not dropped from 15 cm up)
    assert np.linalg.norm(np.subtract(again, first)[:2]) < 0.01, (first, again)


def test_a_run_a_safety_stop_ends_logs_how_far_its_cell_ran_behind(tmp_path):
    """The cycle a safety stop ends is not scored; the run log still says how far the simulated cell ran behind the
    clock in it (`cell_backlog`, `stopped`), the record by which a dry run on a busy PC is told from a policy's
    failure."""
    cfg = CellConfig()
    faults: list[int] = []

    def fault_in_the_grasp(obs, phase, a, cell):
        if phase == Phase.GRASP and not faults:
            cell.sim.inject_drive_fault(5)
            faults.append(5)
        return a

    log = tmp_path / "cycles.jsonl"
    summary = in_process(log, cfg, CycleRun(0, 2, seed=3, config=CycleConfig()), fault_in_the_grasp, [])
    assert summary.stopped is not None and "drive_fault" in summary.stopped, summary.text()
    records = read_log(log)
    assert not [r for r in records if r["kind"] == "scored"]
    (behind,) = [r for r in records if r["kind"] == "cell_backlog"]
    assert behind["stopped"] is True and behind["seconds"] >= 0.0
