"""`mrguide deploy`: a bad policy refused before any drive is enabled, a real bus without confirmation, the
virtual interface without --dry-run; the real-robot path end to end over a virtual channel, and Ctrl-C."""

import numpy as np
import pytest

from mrguide.cli import main
from mrguide.deploy.runlog import read_log
from mrguide.drivers.cobot import Cobot


def test_bad_policy_refused_before_enable(tmp_path, monkeypatch, capsys):
    enabled = []
    monkeypatch.setattr(Cobot, "enable", lambda self, timeout=None: enabled.append(1))
    bad = tmp_path / "bad.npz"
    np.savez(bad, W0=np.zeros((4, 11)))
    assert main(["deploy", "--policy", str(bad), "--dry-run", "--quiet"]) == 2
    assert "no metadata" in capsys.readouterr().err
    assert enabled == []


def test_real_bus_needs_confirmation(tmp_path, monkeypatch, capsys):
    from mrguide.policies.ddpg import DDPG, DDPGConfig
    from mrguide.policies.export import export_actor
    from mrguide.policies.networks import obs_scaling
    from mrguide.robot import load_robot
    from mrguide.task import TaskConfig

    connected = []
    monkeypatch.setattr(Cobot, "connect", lambda self: connected.append(1))
    pol = export_actor(
        DDPG(*obs_scaling(load_robot().workspace), 4, DDPGConfig()).actor,
        tmp_path / "p.npz",
        load_robot(),
        TaskConfig(),
        0.1,
    )
    bus = tmp_path / "bus.toml"
    bus.write_text('[bus]\ninterface = "socketcan"\nchannel = "can0"\n')
    cfg = tmp_path / "cfg.toml"
    cfg.write_text('[deploy]\nbus_config = "bus.toml"\n')
    assert main(["deploy", "--policy", str(pol), "--config", str(cfg), "--quiet"]) == 2
    assert "--enable-drives" in capsys.readouterr().err
    assert connected == []


# -- the real-robot path, driven over a virtual channel ------------------------------------------------------
# `deploy` refuses the virtual interface without --dry-run (users must configure their real bus); the tests
# open that path with the `ALLOW_VIRTUAL_REAL_BUS` seam and put simulated devices (first-order plant, no
# PyBullet) on the channel in place of the robot.

HORIZON = 4
#: A constant action away from the workspace centre, vacuum off: tanh of these biases.
BIASES = np.array([0.8, 0.6, 0.3, -1.0])


def _robot_cell_files(tmp_path, policy_file):
    """Bus description (virtual channel of its own, the shared-PC supervision times), deploy config, policy."""
    from mrguide.config import to_dict
    from mrguide.task import TaskConfig

    channel = f"deploy-real-{tmp_path.name}"
    (tmp_path / "bus.toml").write_text(
        f'[bus]\ninterface = "virtual"\nchannel = "{channel}"\n'
        "[timing]\nheartbeat_period = 0.15\nheartbeat_timeout_factor = 3.0\n"
        "max_missed_feedback = 25\n"
    )
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(f'[deploy]\nbus_config = "bus.toml"\nepisodes = 2\n[task]\nhorizon = {HORIZON}\n')
    policy = policy_file(
        tmp_path / "p.npz", task=to_dict(TaskConfig(horizon=HORIZON)), arrays={"b0": BIASES, "b0_carry": BIASES}
    )
    return cfg, policy


@pytest.fixture
def robot_on_virtual_bus(tmp_path, policy_file, monkeypatch):
    """(config, policy, simulated devices, prompts): the seam opened, the operator's Enter pressed."""
    import mrguide.deploy.commands as deploy_commands
    from mrguide.drivers.config import load_cobot_bus_config
    from mrguide.drivers.mock import FirstOrderPlant, SimulatedCobot
    from mrguide.robot import load_robot

    cfg, policy = _robot_cell_files(tmp_path, policy_file)
    monkeypatch.setattr(deploy_commands, "ALLOW_VIRTUAL_REAL_BUS", True)
    prompts = []
    monkeypatch.setattr("builtins.input", lambda prompt="": prompts.append(prompt) or "")
    robot = load_robot()
    sim = SimulatedCobot(load_cobot_bus_config(tmp_path / "bus.toml", robot), FirstOrderPlant(robot.q_home))
    sim.start()
    try:
        yield cfg, policy, sim, prompts
    finally:
        sim.stop()


def test_real_bus_path_runs_the_policy_on_the_robot(robot_on_virtual_bus, tmp_path, capsys):
    from mrguide.drivers.mock.drive_sim import SWITCH_ON_DISABLED
    from mrguide.robot import load_robot

    cfg, policy, sim, prompts = robot_on_virtual_bus
    log = tmp_path / "log.jsonl"
    assert (
        main(["deploy", "--policy", str(policy), "--config", str(cfg), "--enable-drives", "--log", str(log), "--quiet"])
        == 0
    ), capsys.readouterr().err
    assert "episodes: 2" in capsys.readouterr().out
    assert len(prompts) == 2 and all("place the object at" in p for p in prompts)
    records = read_log(log)
    header = records[0]
    assert header["kind"] == "run" and header["dry_run"] is False and header["bus"].startswith("virtual:deploy-real-")
    ends = [r for r in records if r["kind"] == "episode_end"]
    assert [e["episode"] for e in ends] == [0, 1] and all(e["outcome"] == "no_grasp" for e in ends)
    steps = [r for r in records if r["kind"] == "decision" and "setpoints" in r]
    assert len(steps) == 2 * HORIZON
    spec = load_robot()
    # a constant offset from the part's centre (the part is where the operator put it; the vacuum stays off)
    for r in steps:
        assert np.allclose(
            r["target"], spec.workspace.clamp(np.array(r["obs"][5:8]) + 0.5 * np.tanh(BIASES[:3]))[0], atol=2e-4
        )
    # the simulated drives followed the streamed setpoints away from home, and were disabled at the end
    last = np.array(steps[-1]["setpoints"][-1]) - spec.q_home
    moved = sim.plant.joint_positions() - spec.q_home  # where the arm came to rest after braking
    assert np.max(np.abs(last)) > 0.05
    assert np.all(np.abs(moved) >= np.abs(last) - 1e-3) and np.all(
        np.sign(moved[np.abs(last) > 0.01]) == np.sign(last[np.abs(last) > 0.01])
    )
    assert all(d.state == SWITCH_ON_DISABLED for d in sim.drives)


def test_ctrl_c_quick_stops_exits_130_and_closes_the_log(robot_on_virtual_bus, tmp_path, monkeypatch, capsys):
    from mrguide.deploy.policy import ExportedPolicy
    from mrguide.deploy.runlog import RunLog

    cfg, policy, _sim, _ = robot_on_virtual_bus
    calls, closed = [], []
    real_call, real_close = ExportedPolicy.__call__, RunLog.close

    def interrupted(self, obs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt  # the operator presses Ctrl-C during the third decision
        return real_call(self, obs)

    def close(self):
        real_close(self)
        closed.append(self._fh.closed)

    monkeypatch.setattr(ExportedPolicy, "__call__", interrupted)
    monkeypatch.setattr(RunLog, "close", close)
    log = tmp_path / "log.jsonl"
    code = main(
        ["deploy", "--policy", str(policy), "--config", str(cfg), "--enable-drives", "--log", str(log), "--quiet"]
    )
    assert code == 130
    assert capsys.readouterr().err.strip().endswith("mrguide deploy: interrupted")
    assert closed == [True]
    text = log.read_text()
    assert text.endswith("\n")  # every record whole: nothing torn, nothing lost in a buffer
    records = read_log(log)
    safety = [(r["event"], r["reaction"]) for r in records if r["kind"] == "safety"]
    assert safety == [("interrupt", "quick_stop")]
    ends = [r for r in records if r["kind"] == "episode_end"]
    assert len(ends) == 1 and ends[0]["outcome"] == "safety_stop" and ends[0]["events"] == {"interrupt": 1}
    assert not any(r["kind"] == "episode_start" and r["episode"] == 1 for r in records)


def test_virtual_interface_without_dry_run_is_refused_for_users(tmp_path, policy_file, run_cli, monkeypatch):
    connected = []
    monkeypatch.setattr(Cobot, "connect", lambda self: connected.append(1))
    cfg, policy = _robot_cell_files(tmp_path, policy_file)
    run_cli(["deploy", "--policy", policy, "--config", cfg, "--enable-drives", "--quiet"]).assert_refused(
        "virtual interface", "--dry-run"
    )
    assert connected == []


def test_cycles_on_the_robot_retry_alarm_skip_and_resume(robot_on_virtual_bus, tmp_path, capsys, run_cli):
    """`--cycles` on the real-bus path with the fixed pose (the operator feeds the fixture): this policy never grips,
    so each part is tried twice (one retry), the alarm leaves it for the operator, and the next one is fed;
    `--resume` goes on from the log's count up to --cycles in all."""
    cfg, policy, _sim, prompts = robot_on_virtual_bus
    cfg.write_text(cfg.read_text() + "[deploy.cycles]\nmax_retries = 3\n")
    log = tmp_path / "cycles.jsonl"
    args = ["deploy", "--policy", str(policy), "--config", str(cfg), "--enable-drives", "--log", str(log), "--quiet"]
    args += ["--set", "deploy.cycles.max_retries=1", "--set", "deploy.cycles.on_alarm=skip"]  # after the file's
    assert main([*args, "--cycles", "2"]) == 0, capsys.readouterr().err
    out = capsys.readouterr().out
    assert "cycles 0..1: 0 of 2 parts placed" in out and "retries: {'no_grasp': 2}" in out
    assert [p.split(":")[0] for p in prompts] == ["cycle 0", "cycle 0", "cycle 1", "cycle 1"]
    assert "place the part" in prompts[0] and "remove the part" in prompts[1]
    records = read_log(log)
    assert [r["episode"] for r in records if r["kind"] == "episode_end"] == [0, 1, 2, 3]
    assert [(r["cycle"], r["cause"]) for r in records if r["kind"] == "retry"] == [(0, "no_grasp"), (1, "no_grasp")]
    assert [r["action"] for r in records if r["kind"] == "alarm"] == ["skip", "skip"]

    run_cli([*args, "--cycles", "2", "--resume"]).assert_refused("already holds 2 cycles", "--cycles 2")
    assert len([r for r in read_log(log) if r["kind"] == "run"]) == 1  # refused before the log was opened
    assert main([*args, "--cycles", "3", "--resume"]) == 0
    assert "cycles 2..2" in capsys.readouterr().out
    records = read_log(log)
    assert [h["first_cycle"] for h in records if h["kind"] == "run"] == [0, 2]
    assert [r["episode"] for r in records if r["kind"] == "episode_end"] == [0, 1, 2, 3, 4, 5]  # counted on


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--resume", "--cycles", "1"], ("--resume needs", "--log")),
        (["--cycles", "1", "--episodes", "2"], ("--cycles and --episodes",)),
        (["--cycles", "1", "--resume", "--log", "missing.jsonl"], ("no such run log",)),
        (["--set", "deploy.cycles.max_retries=-1"], ("--set", "deploy.cycles.max_retries")),
        (["--set", "deploy.cycles.nope=1"], ("--set", "cycles.nope", "no such key")),
        (["--set", "twin.gui=true"], ("--set twin.gui", "deploy and safety")),
        (["--set", "safety.stall_timeout=nan"], ("safety.stall_timeout",)),
    ],
)
def test_bad_cycle_arguments_are_refused(tmp_path, policy_file, run_cli, extra, words):
    policy = policy_file(tmp_path / "p.npz")
    extra = [str(tmp_path / e) if e.endswith(".jsonl") else e for e in extra]
    run_cli(["deploy", "--policy", policy, "--dry-run", "--quiet", *extra]).assert_refused(*words)
