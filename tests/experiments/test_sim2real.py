"""The three sim-to-real conditions end to end on a small budget, with the scripted expert as the policy."""

from pathlib import Path

import numpy as np

from mrguide.cell.config import CellConfig
from mrguide.cell.hmd_stream import HmdPoseStream
from mrguide.cli import main
from mrguide.drivers.config import BusConfig, CobotBusConfig
from mrguide.experiments import sim2real as s2r
from mrguide.experiments import sim2real_report
from mrguide.robot import load_robot
from mrguide.task import oracle_action
from mrguide.twin.env import EnvConfig

REAL = Path(__file__).parents[2] / "configs" / "cells" / "real_cell.toml"


def expert(cfg):
    ws = load_robot(cfg.robot).workspace
    return lambda obs: oracle_action(obs, cfg.task, ws.to_normalized)


def test_sim_condition_is_reproducible_per_seed():
    cfg = EnvConfig()
    a = s2r.run_sim(expert(cfg), cfg, seed=4, episodes=3)
    b = s2r.run_sim(expert(cfg), cfg, seed=4, episodes=3)
    assert a == b == ["success"] * 3
    assert all(
        np.array_equal(x[0], y[0]) for x, y in zip(s2r.episode_layouts(cfg, 3, 4), s2r.episode_layouts(cfg, 3, 4))
    )


def test_real_exact_condition(tmp_path):
    cfg = CellConfig.load(REAL)
    bus = CobotBusConfig(bus=BusConfig(channel="s2r-exact"))
    out = s2r.run_real(
        None,
        cfg,
        bus,
        seed=0,
        episodes=2,
        log_path=tmp_path / "log.jsonl",
        hmd_config=REAL,
        safety=None,
        policy=expert(cfg),
    )
    assert out == ["success", "success"]


def test_a_cell_whose_drives_do_not_enable_counts_its_episodes_and_says_why(tmp_path, monkeypatch):
    """A simulated cell that cannot start (its drives not enabled in time, as on a starved PC) costs that seed's
    episodes, counted as safety stops with the reason in the run log; it does not end the experiment."""
    from mrguide.deploy.runlog import read_log
    from mrguide.drivers.errors import DriverError

    def no_enable(*args, **kwargs):
        raise DriverError("drives did not reach OPERATION ENABLED within 1.0 s")

    monkeypatch.setattr(s2r, "dry_run", no_enable)
    cfg = CellConfig.load(REAL)
    bus = CobotBusConfig(bus=BusConfig(channel="s2r-no-enable"))
    seen = []
    out = s2r.run_real(
        None, cfg, bus, 0, 3, tmp_path / "log.jsonl", REAL, None, on_episode=seen.append, policy=expert(cfg)
    )
    assert out == seen == ["safety_stop"] * 3
    stopped = [r for r in read_log(tmp_path / "log.jsonl") if r["kind"] == "run_stopped"]
    assert len(stopped) == 1 and "did not start" in stopped[0]["reason"] and "OPERATION ENABLED" in stopped[0]["reason"]


def test_real_hmd_condition_uses_marker_pipeline_poses(tmp_path, monkeypatch):
    cfg = CellConfig.load(REAL)
    bus = CobotBusConfig(bus=BusConfig(channel="s2r-hmd"))
    seen = []
    original = HmdPoseStream.object_position

    def spy(self):
        est = original(self)
        seen.append((est, self.plant.object_position(), self.frames))
        return est

    monkeypatch.setattr(HmdPoseStream, "object_position", spy)
    out = s2r.run_real(
        None,
        cfg,
        bus,
        seed=0,
        episodes=2,
        log_path=tmp_path / "log.jsonl",
        hmd_config=REAL,
        safety=None,
        policy=expert(cfg),
        use_hmd=True,
    )
    # how often the HMD's pose error costs a part is the sim-to-real experiment's figure, not this test's: a grasp
    # off-centre by the HMD's error can seal partly and drop the part in the lift (the runtime's "vacuum OK" rule is
    # the production issue's), or land beyond the cup's 5 mm seal margin (`mrguide.seal`) and leave the runtime's
    # seal search to spend the horizon (on a busy machine, with fewer fresh HMD frames, 5-7 re-seats: no grasp or a
    # timeout), and a machine too busy for the cell's real time leaves an episode not judged; here, that the episodes
    # ran on the marker pipeline's poses
    judged = {"success", "dropped", "misplaced", "no_grasp", "timeout"}
    assert len(out) == 2 and set(out) <= judged | {s2r.CELL_BEHIND}, out
    assert len(seen) > 10 and max(f for *_, f in seen) > 2
    # poses really came out of the marker pipeline with its noise: never the ground truth, and close to
    # it while the object rests on the table (while carried, the HMD estimate lags the moving object)
    errors = np.array([np.linalg.norm(e - t) for e, t, _ in seen])
    resting = np.array([t[2] < 0.03 for _, t, _ in seen])
    assert np.all(errors > 1e-5)
    assert resting.sum() > 5 and np.median(errors[resting]) < 0.02


def test_report_files(tmp_path):
    res = [s2r.ConditionResult("sim", {0: ["success", "no_grasp"], 1: ["success", "success"]})]
    md = sim2real_report.write_report(res, tmp_path, "gap")
    assert "75 %" in md.read_text() and (tmp_path / "fig8_sim2real.png").stat().st_size > 1000


def test_the_report_describes_only_the_cells_it_played():
    """The PyBullet twin's reality gap under its conditions only, each cell's HMD (as set) under an HMD condition."""
    from dataclasses import replace

    from mrguide.shipped_configs import shipped_config

    real = s2r.load_real_cell(REAL)
    mujoco = s2r.load_real_cell(shipped_config("cells", "mujoco_cell.toml"))
    cells = {"real": real, "mujoco": replace(mujoco, hmd=replace(mujoco.hmd, tracking_noise_m=0.0071))}
    only_mujoco = sim2real_report.cells_description(cells, ["sim", "mujoco_exact", "mujoco_hmd"])
    assert "Reality gap" not in only_mujoco and "mujoco_cell.toml" in only_mujoco
    assert "tracking noise 7.1 mm" in only_mujoco
    exact = sim2real_report.cells_description(cells, ["real_exact", "mujoco_exact"])
    assert "Reality gap" in exact and "mujoco_cell.toml" in exact and "HMD" not in exact
    assert sim2real_report.cells_description(cells, ["sim"]) == ""


def test_cli_refuses_a_bad_policy(tmp_path, capsys):
    bad = tmp_path / "bad.npz"
    np.savez(bad, W0=np.zeros((4, 11)))
    assert main(["sim2real", "--policy", str(bad), "--real-config", str(REAL), "--out", str(tmp_path), "--quiet"]) == 2


def test_sweep_runs_each_value_as_its_type_and_reports_it(tmp_path, run_cli, policy_file, monkeypatch):
    """A sweep reaches the runs with the parameter's own type (whole latencies) and its rows get into the report
    (the figure labels sweep rows by their name)."""
    seen = []

    def run_real(policy_path, cfg, bus, seed, episodes, log_path, *args, hmd_overrides=None, **kwargs):
        seen.append((cfg.twin.reality_gap.actuator_latency, hmd_overrides, seed))
        return ["success"] * episodes

    monkeypatch.setattr(s2r, "run_real", run_real)
    out = tmp_path / "out"
    result = run_cli(
        [
            "sim2real",
            "--policy",
            policy_file(tmp_path / "p.npz"),
            "--real-config",
            REAL,
            "--out",
            out,
            "--quiet",
            "--seeds",
            2,
            "--episodes",
            3,
            "--sweep",
            "actuator_latency=0,3",
            "--sweep",
            "tracking_noise_m=0.004",
        ]
    )
    assert result.code == 0, result.err
    assert seen == [
        (0, None, 0),
        (0, None, 1),
        (3, None, 0),
        (3, None, 1),
        (2, {"tracking_noise_m": 0.004}, 0),
        (2, {"tracking_noise_m": 0.004}, 1),
    ]
    assert all(type(latency) is int for latency, *_ in seen)
    rows = (out / "sim2real.csv").read_text().splitlines()
    assert [r.split(",")[0] for r in rows[1:]] == [
        "real_exact actuator_latency=0",
        "real_exact actuator_latency=3",
        "real_hmd tracking_noise_m=0.004",
    ]
    assert (out / "fig8_sim2real.png").stat().st_size > 1000 and "| real_hmd tracking_noise_m=0.004 |" in result.out
    assert sorted(p.name for p in out.iterdir()) == ["fig8_sim2real.png", "sim2real.csv", "sim2real.md"]


def test_an_episode_the_simulated_cell_played_behind_the_clock_is_voided_with_what_its_stop_left_unplayed():
    from mrguide.deploy.episode import EpisodeReport
    from mrguide.deploy.session import DeploySummary
    from mrguide.task import Outcome, TaskConfig

    hooks = s2r._SeedHooks(TaskConfig(), [np.zeros(3)] * 4, [], None)
    hooks.judge(EpisodeReport(0, Outcome.NO_GRASP, 60, {}, cell_backlog_s=0.05))  # on time: the policy's outcome
    hooks.judge(EpisodeReport(1, Outcome.SAFETY_STOP, 44, {}, cell_backlog_s=1.3))  # 1.3 s behind: not judged
    assert hooks.finish(DeploySummary(), 0, 4) == ["no_grasp", "cell_behind", "cell_behind", "cell_behind"]
