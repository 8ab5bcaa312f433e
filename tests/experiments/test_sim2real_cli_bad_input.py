"""`mrguide sim2real` and `mrguide main` with bad input: one line on stderr naming what and where, exit 2,
before the first episode runs, and no output directory, CSV or run log written."""

from __future__ import annotations

from pathlib import Path

import pytest

from mrguide.experiments import sim2real as s2r

REAL = Path(__file__).parents[2] / "configs" / "cells" / "real_cell.toml"


@pytest.fixture
def no_episodes(monkeypatch):
    """Fail the test if an episode of any condition runs."""

    def ran(*args, **kwargs):
        raise AssertionError("an episode ran before the input was refused")

    monkeypatch.setattr(s2r, "run_sim", ran)
    monkeypatch.setattr(s2r, "run_real", ran)


def _real_config(d: Path, old: str, new: str) -> list:
    """--real-config with a copy of configs/cells/real_cell.toml whose line `old` is replaced by `new` (beside a copy
    of the bus config it names, in the same layout)."""
    (d / "devices").mkdir(exist_ok=True)
    (d / "devices" / "cobot_bus.toml").write_text((REAL.parents[1] / "devices" / "cobot_bus.toml").read_text())
    text = REAL.read_text()
    assert old in text and 'bus_config = "../devices/cobot_bus.toml"' in text
    (d / "cells").mkdir(exist_ok=True)
    path = d / "cells" / "real.toml"
    path.write_text(text.replace(old, new))
    return ["--real-config", path]


CASES = [
    # (id, argv after --policy/--out given the tmp dir, words in the one stderr line)
    ("--seeds 0", lambda d: ["--seeds", "0"], ["--seeds", "'0'"]),
    ("--seeds -1", lambda d: ["--seeds", "-1"], ["--seeds"]),
    ("--episodes -1", lambda d: ["--episodes", "-1"], ["--episodes", "'-1'"]),
    ("--episodes 0", lambda d: ["--episodes", "0"], ["--episodes"]),
    ("--conditions ,", lambda d: ["--conditions", ","], ["--conditions", "','"]),
    ("--conditions unknown", lambda d: ["--conditions", "sim,real"], ["--conditions", "'sim,real'"]),
    ("--conditions twice", lambda d: ["--conditions", "sim,sim"], ["--conditions", "distinct"]),
    ("--sweep nan", lambda d: ["--sweep", "actuator_latency=nan"], ["--sweep", "actuator_latency=nan", "finite"]),
    ("--sweep inf", lambda d: ["--sweep", "actuator_lag=0.01,inf"], ["--sweep", "finite"]),
    ("--sweep latency 1.5", lambda d: ["--sweep", "actuator_latency=1.5"], ["--sweep", "whole numbers"]),
    ("--sweep not a number", lambda d: ["--sweep", "object_mass=heavy"], ["--sweep", "must be numbers"]),
    ("--sweep no values", lambda d: ["--sweep", "object_mass="], ["--sweep", "PARAM=v1,v2"]),
    ("--sweep unknown", lambda d: ["--sweep", "gravity=9.8"], ["--sweep", "'gravity=9.8'"]),
    ("--sweep mass -1", lambda d: ["--sweep", "object_mass=0.2,-1"], ["--sweep object_mass=-1.0", "object_mass"]),
    (
        "--sweep HMD noise 5 m",
        lambda d: ["--sweep", "tracking_noise_m=5"],
        ["--sweep tracking_noise_m=5.0", "calibration.hmd.tracking_noise_m = 5.0"],
    ),
    ("--out under a file", lambda d: ["--out", d / "afile" / "out"], ["--out", "afile", "is not a directory"]),
    (
        "reality gap nan",
        lambda d: _real_config(d, "actuator_lag = 0.015", "actuator_lag = nan"),
        ["real.toml [twin]", "reality_gap.actuator_lag = nan"],
    ),
    (
        "reality gap latency 1.5",
        lambda d: _real_config(d, "actuator_latency = 2", "actuator_latency = 1.5"),
        ["real.toml [twin]", "reality_gap.actuator_latency = 1.5"],
    ),
    (
        "HMD seed -1",
        lambda d: _real_config(d, "[calibration.hmd]", "[calibration.hmd]\nseed = -1"),
        ["real.toml [calibration]", "hmd.seed = -1"],
    ),
    ("--set not a key", lambda d: ["--set", "object_mass"], ["--set", "SECTION.KEY=VALUE"]),
    (
        "--set a section sim2real does not set",
        lambda d: ["--set", "deploy.bus_config=x"],
        ["--set deploy.bus_config", "sim2real sets keys of the played cell's twin, task"],
    ),
    ("--set unknown key", lambda d: ["--set", "twin.gravity=9.8"], ["--set twin.gravity", "no such key"]),
    (
        "--set mass -1",
        lambda d: ["--set", "twin.reality_gap.object_mass=-1"],
        ["--set twin.reality_gap.object_mass", "object_mass"],
    ),
    (
        "--set HMD noise 5 m",
        lambda d: ["--set", "calibration.hmd.tracking_noise_m=5"],
        ["--set calibration.hmd.tracking_noise_m", "tracking_noise_m"],
    ),
    ("--set safety", lambda d: ["--set", "safety.following_error=7"], ["--set safety.following_error"]),
    ("policy decision period 0.2", lambda d: ["--policy", d / "p2.npz"], ["p2.npz", "0.2 s decision period"]),
    ("bad policy", lambda d: ["--policy", d / "afile"], ["afile", "not a readable policy file"]),
]


@pytest.mark.parametrize("make_argv, words", [c[1:] for c in CASES], ids=[c[0] for c in CASES])
def test_bad_input_is_refused_before_any_episode(tmp_path, run_cli, policy_file, no_episodes, make_argv, words):
    (tmp_path / "afile").write_text("in the way")
    policy_file(tmp_path / "p2.npz", decision_period=0.2)
    out = tmp_path / "out"
    run_cli(
        [
            "sim2real",
            "--policy",
            policy_file(tmp_path / "p.npz"),
            "--real-config",
            REAL,
            "--out",
            out,
            "--quiet",
            *make_argv(tmp_path),
        ]
    ).assert_refused(*words)
    assert not out.exists() and not (tmp_path / "afile" / "out").exists()


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--train-steps", "0"], ["--train-steps"]),
        (["--deploy-episodes", "-1"], ["--deploy-episodes"]),
        (["--seeds", "0"], ["--seeds"]),
        (["--episodes", "x"], ["--episodes", "'x'"]),
        (["--seed", "-3"], ["--seed", "'-3'"]),
    ],
)
def test_main_job_refuses_bad_numbers_at_parse_time(tmp_path, run_cli, argv, words):
    run_cli(["main", "--out", tmp_path / "main", *argv]).assert_refused(*words)
    assert not (tmp_path / "main").exists()
