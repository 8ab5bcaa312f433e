"""`mrguide deploy` with bad input: one line on stderr naming what and where, exit 2, before any drive is
enabled (or, on a real bus, before anything is connected), and no run log left behind.

A run that fails after the checks keeps a run log with its header record.
"""

from __future__ import annotations

import numpy as np
import pytest

from mrguide.deploy.runlog import read_log
from mrguide.drivers.cobot import Cobot
from mrguide.drivers.errors import DriverError
from mrguide.task import ACT_DIM, OBS_DIM


@pytest.fixture
def calls(monkeypatch):
    """Every Cobot.connect and Cobot.enable, in order."""
    seen: list[str] = []
    real_connect, real_enable = Cobot.connect, Cobot.enable
    monkeypatch.setattr(Cobot, "connect", lambda self: (seen.append("connect"), real_connect(self))[1])
    monkeypatch.setattr(
        Cobot, "enable", lambda self, timeout=None: (seen.append("enable"), real_enable(self, timeout))[1]
    )
    return seen


@pytest.fixture
def cell(tmp_path):
    """Config files for the tests: a virtual bus of its own, a real bus, a bus with five drives, a file in the way."""
    (tmp_path / "bus.toml").write_text(f'[bus]\nchannel = "deploy-bad-input-{tmp_path.name}"\n')
    (tmp_path / "real_bus.toml").write_text('[bus]\ninterface = "socketcan"\nchannel = "mrguide-no-if"\n')
    (tmp_path / "five.toml").write_text("[[joints]]\n" * 5)
    (tmp_path / "afile").write_text("in the way")
    return tmp_path


def _config(d, name="cfg.toml", deploy='bus_config = "bus.toml"', extra=""):
    path = d / name
    path.write_text(f"[deploy]\n{deploy}\n{extra}")
    return path


POLICY_CASES = [
    # (id, policy_file arguments, words in the one stderr line)
    ("decision period 0.2", {"decision_period": 0.2}, ["p.npz", "trained with a 0.2 s decision period", "runs 0.1 s"]),
    ("decision period true", {"decision_period": True}, ["p.npz", "decision_period"]),
    ("decision period inf", {"decision_period": float("inf")}, ["p.npz", "decision_period"]),
    ("decision period 1e6 s", {"decision_period": 1e6}, ["p.npz", "decision_period in (0, 10] s", "1000000.0"]),
    ("metadata a list", {"metadata": ["format"]}, ["p.npz", "metadata is a JSON list"]),
    ("metadata a number", {"metadata": 3}, ["p.npz", "metadata is a JSON int"]),
    ("workspace missing", {"drop": ("workspace",)}, ["p.npz", "metadata workspace None"]),
    ("workspace a string", {"workspace": "big"}, ["p.npz", "metadata workspace 'big'"]),
    ("workspace inf", {"workspace": {"low": [0, 0, 0], "high": [1, 1, float("inf")]}}, ["p.npz", "workspace"]),
    ("workspace 2-d", {"workspace": {"low": [0.3, -0.3], "high": [0.7, 0.3]}}, ["p.npz", "workspace", "not a box"]),
    ("workspace 4-d", {"workspace": {"low": [0, 0, 0, 0], "high": [1, 1, 1, 1]}}, ["p.npz", "workspace", "not a box"]),
    ("workspace 1-d", {"workspace": {"low": [0.3], "high": [0.7]}}, ["p.npz", "workspace", "not a box"]),
    ("task a list", {"task": [1, 2]}, ["p.npz", "metadata task [1, 2]"]),
    ("activations a string", {"activations": "tanh"}, ["p.npz", "activations 'tanh'"]),
    ("activations a number", {"activations": 1}, ["p.npz", "activations 1"]),
    ("layout a number", {"obs_layout": 11}, ["p.npz", "layout"]),
    ("string weights", {"arrays": {"W0": np.full((ACT_DIM, OBS_DIM), "a")}}, ["p.npz", "W0", "<U1"]),
    ("complex weights", {"arrays": {"b0": np.zeros(ACT_DIM, complex)}}, ["p.npz", "b0", "complex128"]),
    ("boolean weights", {"arrays": {"W0": np.zeros((ACT_DIM, OBS_DIM), bool)}}, ["p.npz", "W0", "bool"]),
    ("layer missing", {"activations": ["tanh", "tanh"]}, ["p.npz", "'W1' missing"]),
]


@pytest.mark.parametrize("policy, words", [c[1:] for c in POLICY_CASES], ids=[c[0] for c in POLICY_CASES])
def test_bad_policy_file_is_refused_before_enabling(cell, calls, run_cli, policy_file, policy, words):
    log = cell / "log.jsonl"
    run_cli(
        [
            "deploy",
            "--policy",
            policy_file(cell / "p.npz", **policy),
            "--config",
            _config(cell),
            "--dry-run",
            "--episodes",
            1,
            "--log",
            log,
            "--quiet",
        ]
    ).assert_refused(*words)
    assert calls == [] and not log.exists()


def test_real_bus_refuses_a_decision_period_the_control_cycle_cannot_run(cell, calls, run_cli, policy_file):
    policy = policy_file(cell / "p.npz", decision_period=0.006)
    run_cli(
        [
            "deploy",
            "--policy",
            policy,
            "--config",
            _config(cell, deploy='bus_config = "real_bus.toml"'),
            "--enable-drives",
            "--log",
            cell / "log.jsonl",
            "--quiet",
        ]
    ).assert_refused("p.npz", "decision period 0.006 s is not a whole number of control periods (0.004 s)")
    assert calls == [] and not (cell / "log.jsonl").exists()


def _log(d):
    return ["--log", d / "log.jsonl"]


RUN_CASES = [
    # (id, argv after the policy and config given the tmp dir, config given the tmp dir, words)
    ("--episodes -1", lambda d: ["--episodes", "-1", *_log(d)], _config, ["--episodes", "'-1'"]),
    ("--episodes 0", lambda d: ["--episodes", "0", *_log(d)], _config, ["--episodes", "'0'"]),
    ("--episodes nan", lambda d: ["--episodes", "nan", *_log(d)], _config, ["--episodes", "'nan'"]),
    ("--episodes 1.5", lambda d: ["--episodes", "1.5", *_log(d)], _config, ["--episodes", "'1.5'"]),
    ("--seed -1", lambda d: ["--seed", "-1", *_log(d)], _config, ["--seed", "'-1'"]),
    (
        "--log /dev/full",
        lambda d: ["--log", "/dev/full"],
        _config,
        ["--log /dev/full", "cannot write the run log", "No space left on device"],
    ),
    (
        "--log under a file",
        lambda d: ["--log", d / "afile" / "log.jsonl"],
        _config,
        ["--log", "afile", "cannot create"],
    ),
    ("--log a directory", lambda d: ["--log", d], _config, ["--log", "cannot create the run log"]),
    (
        "log_dir under a file",
        lambda d: [],
        lambda d: _config(d, deploy='bus_config = "bus.toml"\nlog_dir = "afile/logs"'),
        ["cfg.toml [deploy] log_dir", "afile", "cannot create the run log"],
    ),
    (
        "[deploy] episodes 0",
        _log,
        lambda d: _config(d, deploy='bus_config = "bus.toml"\nepisodes = 0'),
        ["cfg.toml [deploy]", "deploy.episodes = 0"],
    ),
    (
        "[deploy] goals empty",
        _log,
        lambda d: _config(d, deploy='bus_config = "bus.toml"\ngoals = []'),
        ["cfg.toml [deploy]", "deploy.goals"],
    ),
    (
        "[deploy] goal nan",
        _log,
        lambda d: _config(d, deploy='bus_config = "bus.toml"\ngoals = [[0.5, nan, 0.0]]'),
        ["cfg.toml [deploy]", "goals[0][1] = nan"],
    ),
    (
        "five drives",
        _log,
        lambda d: _config(d, deploy='bus_config = "five.toml"'),
        ["five.toml", "joints: 5 drives configured"],
    ),
    (
        "dry run on a real bus",
        _log,
        lambda d: _config(d, deploy='bus_config = "real_bus.toml"'),
        ["--dry-run needs the virtual CAN interface", "'socketcan'"],
    ),
    (
        "key with a line break",
        _log,
        lambda d: _config(d, deploy='bus_config = "bus.toml"\n"a\\nb" = 1'),
        ["cfg.toml [deploy]", '"a\\nb"'],
    ),
    (
        "[safety] stall_timeout nan",
        _log,
        lambda d: _config(d, extra="[safety]\nstall_timeout = nan\n"),
        ["cfg.toml [safety]", "stall_timeout = nan"],
    ),
]


@pytest.mark.parametrize("make_argv, make_config, words", [c[1:] for c in RUN_CASES], ids=[c[0] for c in RUN_CASES])
def test_bad_options_and_configs_are_refused_before_enabling(
    cell, calls, run_cli, policy_file, monkeypatch, make_argv, make_config, words
):
    monkeypatch.chdir(cell)
    run_cli(
        [
            "deploy",
            "--policy",
            policy_file(cell / "p.npz"),
            "--config",
            make_config(cell),
            "--dry-run",
            *make_argv(cell),
            "--quiet",
        ]
    ).assert_refused(*words)
    assert calls == []
    assert not (cell / "log.jsonl").exists() and not (cell / "runs").exists()


def test_real_bus_without_confirmation_is_refused_in_one_line(cell, calls, run_cli, policy_file):
    run_cli(
        [
            "deploy",
            "--policy",
            policy_file(cell / "p.npz"),
            "--config",
            _config(cell, deploy='bus_config = "real_bus.toml"'),
            "--log",
            cell / "log.jsonl",
            "--quiet",
        ]
    ).assert_refused("socketcan:mrguide-no-if", "--enable-drives")
    assert calls == [] and not (cell / "log.jsonl").exists()


def test_a_run_that_fails_keeps_its_run_log_header(cell, calls, run_cli, policy_file, monkeypatch):
    """The drives fail to enable: exit 1, and the run log holds the run's metadata (not an empty file)."""

    def fail(self, timeout=None):
        raise DriverError("drives did not reach OPERATION ENABLED (test)")

    monkeypatch.setattr(Cobot, "enable", fail)
    log = cell / "log.jsonl"
    result = run_cli(
        [
            "deploy",
            "--policy",
            policy_file(cell / "p.npz"),
            "--config",
            _config(cell),
            "--dry-run",
            "--episodes",
            2,
            "--seed",
            7,
            "--log",
            log,
            "--quiet",
        ]
    )
    assert result.code == 1 and "OPERATION ENABLED (test)" in result.err
    header, *rest = read_log(log)
    assert header["kind"] == "run" and header["dry_run"] is True and header["episodes"] == 2 and header["seed"] == 7
    assert header["policy"].endswith("p.npz") and header["decision_period"] == 0.1
    assert rest == []
