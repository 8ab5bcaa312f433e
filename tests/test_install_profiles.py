"""The install profiles: `pip install 'mrguide[robot]'` into a fresh venv runs the robot PC's commands, and
torch, PyBullet and Ray are not in it; a command whose profile is missing says which extra to install.

The robot venv is real: the checkout's wheel (built as the annotation page's wheel test builds it) installed
with its `robot` extra from the package index into `python -m venv`, nothing else (by uv, as run.sh installs: the
versions pip resolves, benchmarks/install.py). The bare install (no extra)
is played in this interpreter by a finder that refuses every module the extras provide.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
import textwrap
import tomllib
from pathlib import Path

import numpy as np
import pytest

from mrguide.install_profiles import MODULES, PROFILES
from tests.conftest import build_wheel
from tests.selftest_verdict import assert_selftest_ran

ROOT = Path(__file__).parents[1]
TRAIN_LINE = "needs the workstation install: pip install 'mrguide[train]' (missing: "
REPLAY_LINE = "needs the replay install: pip install 'mrguide[replay]' (missing: "
ROBOT_LINE = "needs the robot install: pip install 'mrguide[robot]' (missing: "


def _requirement_name(requirement: str) -> str:
    return re.match(r"[A-Za-z0-9._-]+", requirement).group(0).lower()


def test_the_module_map_matches_the_extras_in_pyproject():
    """Every module the message knows comes from a distribution its extra lists, and every distribution of the
    robot and train extras is known (example-robot-data has no module: mrguide.urdf names its extra itself)."""
    extras = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert set(PROFILES) <= set(extras)
    for extra in PROFILES:
        listed = {_requirement_name(r) for r in extras[extra]} - {"mrguide", "example-robot-data"}
        assert listed == {dist for dist, e in MODULES.values() if e == extra}, extra
    assert "mrguide[robot]" in extras["train"]  # the workstation runs the robot commands too (and the twin needs them)


# -- the bare install, played here ----------------------------------------------------------------------------

BARE = """
import sys

BLOCKED = {blocked!r}


class _NotInstalled:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None


sys.meta_path.insert(0, _NotInstalled())
import mrguide.cli

sys.exit(mrguide.cli.main(sys.argv[1:]))
"""


@pytest.fixture
def bare(tmp_path):
    """bare(*argv) -> CompletedProcess: `mrguide argv` where no module of any extra can be imported."""
    script = tmp_path / "bare.py"
    script.write_text(BARE.format(blocked=sorted(MODULES)))

    def run(*argv: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, str(script), *argv],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=300,
            env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"},
        )

    return run


def test_the_bare_install_prints_help(bare):
    for argv in ([], ["deploy"], ["bus", "selftest"], ["train"], ["experiment", "report"]):
        result = bare(*argv, "--help")
        assert result.returncode == 0 and result.stdout.startswith("usage: mrguide"), (argv, result.stderr)


@pytest.mark.parametrize(
    "argv, line",
    [
        (["bus", "selftest"], "mrguide bus selftest " + ROBOT_LINE + "python-can)"),
        (["deploy", "--policy", "p.npz"], "mrguide deploy " + ROBOT_LINE + "opencv-python-headless)"),
        (["calibrate", "--images", "."], "mrguide calibrate " + ROBOT_LINE + "opencv-python-headless)"),
        (["camera", "check"], "mrguide camera check " + ROBOT_LINE + "opencv-python-headless)"),
        (["train", "--out", "t"], "mrguide train " + TRAIN_LINE + "torch)"),
        (["replay", "run.jsonl", "--save", "r.rrd"], "mrguide replay " + REPLAY_LINE + "rerun-sdk)"),
        (["export", "lerobot", "t", "--out", "d"], "mrguide export lerobot " + REPLAY_LINE + "pyarrow)"),
    ],
)
def test_the_bare_install_names_the_extra_a_command_needs(bare, argv, line):
    result = bare(*argv)
    assert (result.returncode, result.stderr, result.stdout) == (2, line + "\n", "")


def test_a_module_of_no_extra_keeps_its_traceback(monkeypatch, capsys):
    """A module no extra provides (a broken install, say) is no missing profile: the error goes up as it is.
    A submodule of a profile's package names the package."""
    from mrguide.cli import main

    def missing(name):
        def handler(args):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)

        return handler

    monkeypatch.setattr("mrguide.drivers.commands._selftest_command", missing("pyparsing"))
    with pytest.raises(ModuleNotFoundError, match="pyparsing"):
        main(["bus", "selftest"])
    monkeypatch.setattr("mrguide.drivers.commands._selftest_command", missing("canopen.objectdictionary"))
    assert main(["bus", "selftest"]) == 2
    assert capsys.readouterr().err == "mrguide bus selftest " + ROBOT_LINE + "canopen)\n"


# -- the robot profile, really installed ----------------------------------------------------------------------


@pytest.fixture(scope="module")
def robot_venv(tmp_path_factory):
    """A fresh venv with the checkout's wheel and its `robot` extra (and nothing else); removed afterwards
    (Pinocchio's libraries make it about 1 GB)."""
    where = tmp_path_factory.mktemp("robot_venv")
    wheel = build_wheel(where)
    venv = where / "venv"
    try:
        subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, capture_output=True, timeout=300)
        # uv (the dev extra's, as run.sh installs with it): the packages pip would install, from its cache where
        # run.sh's install left them; without bytecode, which the modules the tests import write as they load
        uv = [str(Path(sys.executable).parent / "uv"), "pip", "install", "-q", "--python", str(venv / "bin" / "python")]
        install = subprocess.run(
            [*uv, f"{wheel}[robot]"], cwd=where, env=_venv_env(venv), capture_output=True, text=True, timeout=1200
        )
        assert install.returncode == 0, install.stderr[-3000:]
        yield venv
    finally:
        shutil.rmtree(venv, ignore_errors=True)


def _in_venv(venv: Path, argv: list[str], cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    """Run `argv` (its first item a program in the venv's bin/) apart from the checkout: in `cwd`, without
    PYTHONPATH (pip would take the checkout's mrguide.egg-info for an installed mrguide and skip it)."""
    return subprocess.run(
        [str(venv / "bin" / argv[0]), *argv[1:]],
        cwd=cwd,
        env=_venv_env(venv),
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def _venv_env(venv: Path) -> dict[str, str]:
    """The environment without PYTHON* variables, the venv's bin/ first on PATH."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("PYTHON")}
    env["PATH"] = f"{venv / 'bin'}:/usr/bin:/bin"
    env["UV_LINK_MODE"] = "copy"
    return env


def _script(venv: Path, code: str, cwd: Path) -> subprocess.CompletedProcess:
    path = cwd / "script.py"
    path.write_text(textwrap.dedent(code))
    return _in_venv(venv, ["python", str(path)], cwd)


def test_the_robot_venv_has_no_torch_pybullet_or_ray(robot_venv, tmp_path):
    result = _script(
        robot_venv,
        """
        import importlib, importlib.metadata, json
        import mrguide

        failed = {}
        for name in ("torch", "pybullet", "ray", "gymnasium", "matplotlib"):
            try:
                importlib.import_module(name)
            except ModuleNotFoundError as exc:
                failed[name] = exc.name
        print(json.dumps({"failed": failed, "mrguide": mrguide.__file__,
                          "dists": sorted(d.metadata["Name"].lower() for d in importlib.metadata.distributions())}))
        """,
        tmp_path,
    )
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["failed"] == {n: n for n in ("torch", "pybullet", "ray", "gymnasium", "matplotlib")}
    assert Path(report["mrguide"]).is_relative_to(robot_venv)  # the installed copy, not the checkout
    assert not {"torch", "pybullet", "ray"} & set(report["dists"])
    assert {"pin", "ruckig", "python-can", "canopen", "opencv-python-headless", "example-robot-data"} <= set(
        report["dists"]
    )
    check = _in_venv(robot_venv, ["python", "-m", "pip", "check"], tmp_path)
    assert check.returncode == 0, check.stdout + check.stderr


def test_the_robot_venv_prints_help_and_runs_the_bus_selftest(robot_venv, tmp_path):
    for argv in (["--help"], ["deploy", "--help"], ["bus", "selftest", "--help"], ["calibrate", "--help"]):
        result = _in_venv(robot_venv, ["mrguide", *argv], tmp_path)
        assert result.returncode == 0 and result.stdout.startswith("usage: mrguide"), (argv, result.stderr)
    result = _in_venv(robot_venv, ["mrguide", "bus", "selftest"], tmp_path)  # simulated devices, virtual bus
    assert "Traceback" not in result.stderr, result.stderr
    assert_selftest_ran(result.returncode, result.stdout)


@pytest.fixture(scope="module")
def trained_policy(tmp_path_factory) -> Path:
    """A policy file exported from a (fresh) DDPG actor here, in torch, for a 3-step task; beside it probe.npz:
    observations in every phase of both heads and the actions torch gives for them."""
    import torch

    from mrguide.policies.ddpg import DDPG, DDPGConfig
    from mrguide.policies.export import export_actor
    from mrguide.policies.networks import obs_scaling
    from mrguide.robot import load_robot
    from mrguide.task import OBS_DIM, TaskConfig

    folder = tmp_path_factory.mktemp("trained_policy")
    spec = load_robot()
    ws = spec.workspace
    agent = DDPG(*obs_scaling(ws), 4, DDPGConfig(), seed=5)
    path = export_actor(agent.actor, folder / "policy.npz", spec, TaskConfig(horizon=3), 0.1)
    rng = np.random.default_rng(0)
    n = 64  # tcp, vacuum, phase, object, goal (mrguide.task.OBS_LAYOUT)
    obs = np.concatenate(
        [
            rng.uniform(ws.lo, ws.hi, (n, 3)),
            rng.choice([-1.0, 1.0], (n, 1)),
            rng.choice([0.0, 0.2, 0.4, 0.6, 0.8, 1.0], (n, 1)),
            rng.uniform(ws.lo, ws.hi, (n, 3)),
            rng.uniform(ws.lo, ws.hi, (n, 3)),
        ],
        axis=1,
    ).astype(np.float32)
    assert obs.shape[1] == OBS_DIM
    with torch.no_grad():
        expected = agent.actor(torch.as_tensor(obs)).numpy()
    np.savez(folder / "probe.npz", obs=obs, expected=expected)
    return path


def test_the_robot_venv_runs_a_trained_policy_as_torch_does_and_deploys_it(robot_venv, trained_policy, tmp_path):
    """The policy exported from torch here gives the same actions through the numpy runner there, and `mrguide
    deploy` drives it over a virtual channel to simulated drives (the real-bus path, through the
    ALLOW_VIRTUAL_REAL_BUS seam) for one short episode."""
    for name in ("policy.npz", "probe.npz"):
        shutil.copy(trained_policy.parent / name, tmp_path / name)
    (tmp_path / "bus.toml").write_text(
        '[bus]\ninterface = "virtual"\nchannel = "robot-venv"\n'
        "[timing]\nheartbeat_period = 0.15\nheartbeat_timeout_factor = 3.0\nmax_missed_feedback = 25\n"
    )
    (tmp_path / "cfg.toml").write_text('[deploy]\nbus_config = "bus.toml"\nepisodes = 1\n[task]\nhorizon = 3\n')

    result = _script(
        robot_venv,
        """
        import builtins, json, sys
        import numpy as np
        import mrguide.cli as cli
        import mrguide.deploy.commands as deploy_commands
        from mrguide.deploy.policy import ExportedPolicy
        from mrguide.drivers.config import load_cobot_bus_config
        from mrguide.drivers.mock import FirstOrderPlant, SimulatedCobot
        from mrguide.robot import load_robot
        from mrguide.task import TaskConfig

        probe = np.load("probe.npz")
        got = ExportedPolicy.load("policy.npz", load_robot(), TaskConfig(horizon=3)).batch(probe["obs"])
        print(json.dumps({"max_error": float(np.max(np.abs(got - probe["expected"])))}))

        deploy_commands.ALLOW_VIRTUAL_REAL_BUS = True
        builtins.input = lambda prompt="": ""  # the operator's confirmation
        robot = load_robot()
        sim = SimulatedCobot(load_cobot_bus_config("bus.toml", robot), FirstOrderPlant(robot.q_home))
        sim.start()
        try:
            code = cli.main(["deploy", "--policy", "policy.npz", "--config", "cfg.toml", "--enable-drives",
                             "--log", "deploy.jsonl", "--quiet"])
        finally:
            sim.stop()
        print("loaded:", sorted({m.split(".")[0] for m in sys.modules} & {"torch", "pybullet", "ray"}))
        sys.exit(code)
        """,
        tmp_path,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    first = result.stdout.splitlines()[0]
    assert json.loads(first)["max_error"] < 1e-5
    assert "episodes: 1" in result.stdout and "loaded: []" in result.stdout
    records = [json.loads(line) for line in (tmp_path / "deploy.jsonl").read_text().splitlines()]
    assert sum(r["kind"] == "decision" and "setpoints" in r for r in records) == 3


@pytest.mark.parametrize(
    "argv, missing",
    [
        (["train", "--stop-after", "1", "--out", "t"], "torch"),
        (["deploy", "--policy", "policy.npz", "--config", "cfg.toml", "--dry-run"], None),
        (["calibrate", "--twin"], "pybullet"),
        (["experiment", "report", "learning-curves"], None),
        (["annotate", "bot", "--url", "ws://127.0.0.1:9/"], None),
    ],
)
def test_the_robot_venv_names_the_workstation_install_for_the_rest(robot_venv, trained_policy, tmp_path, argv, missing):
    """One line, exit 2, no traceback. (Which package a command misses first is its import order's business,
    except where it can only be the named one.)"""
    shutil.copy(trained_policy, tmp_path / "policy.npz")
    (tmp_path / "cfg.toml").write_text("[task]\nhorizon = 3\n")  # the policy's
    result = _in_venv(robot_venv, ["mrguide", *argv], tmp_path)
    assert result.returncode == 2, result.stdout + result.stderr
    assert result.stderr.count("\n") == 1 and result.stderr.startswith(f"mrguide {argv[0]} {TRAIN_LINE}"), result.stderr
    if missing:
        assert result.stderr.endswith(f"(missing: {missing})\n")
    assert not (tmp_path / "t").exists()
