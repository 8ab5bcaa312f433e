"""Shared by the tests: the realtime marker (and which realtime failures had a simulated cell behind the clock), and
the CLI tests' helpers."""

from __future__ import annotations

import fcntl
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable, Generator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mrguide.deploy.episode import MAX_CELL_BACKLOG_S
from mrguide.deploy.runlog import RunLog

#: MuJoCo's offscreen renderer (the MuJoCo cell's HMD, drawn in-process by its tests) needs an OpenGL context without a
#: display; mujoco reads the variable once, at its import (run.sh installs Debian's EGL).
os.environ.setdefault("MUJOCO_GL", "egl")

#: The DDPG update runs eagerly in the tests (torch reads the variable at its import; the processes the tests start,
#: Ray's workers and the learner's among them, inherit it): building the compiled update costs every new process 4-5 s
#: even from TorchInductor's cache, about a minute of the README's test command. The compiled build is checked
#: against the eager arithmetic once, in tests/policies/test_ddpg_update.py, which turns the compiler back on.
os.environ.setdefault("TORCH_COMPILE_DISABLE", "1")

#: Tests that keep time with threads (simulated CANopen devices on the virtual bus, dry runs, the sim-to-real
#: conditions): `./run.sh test` runs them in a pass of their own (two workers), after the rest, so that a test that
#: computes flat out on both cores never shares the machine with a control cycle: a cycle starved for a few hundred ms
#: is a (correct) safety stop, not a failure of the code.
REALTIME = (
    "tests/deploy/",
    "tests/drivers/",
    "tests/cell/",
    "tests/experiments/test_sim2real",
    "tests/replay/test_replay.py",
    "tests/test_install_profiles.py",
    "tests/test_robot_pc_imports.py",
    "tests/tools/test_press_probe.py",
)


#: Of those, the tests that only compute (the production cycles' runner and rules, driven by fakes): the first pass.
COMPUTE_ONLY = (
    "tests/deploy/test_cycles.py",
    "tests/deploy/test_cycle_report.py",
    "tests/deploy/test_lift_rule.py",
    "tests/deploy/test_seal_search.py",
)


#: The file (environment variable) where the realtime pass of `./run.sh test` has its failed tests listed, one line
#: each: "behind NODEID" when a simulated cell of the test ran behind the clock, "on-time NODEID" otherwise. run.sh
#: runs the first kind again, alone, when the pass failed only so.
FAILED_REALTIME = "MRGUIDE_FAILED_REALTIME"

#: The backlogs (s) the dry runs of the test being run wrote to their run logs (`cell_backlog`, and `scored` cycles):
#: how far each simulated cell ran behind the wall clock.
_backlogs: list[float] = []


def _recording(write: Callable[..., None]) -> Callable[..., None]:
    """`RunLog.write`, first keeping the simulated cells' backlogs it writes in `_backlogs`."""

    def record(self: RunLog, kind: str, **fields: Any) -> None:
        if kind == "cell_backlog" or kind == "scored":
            _backlogs.append(float(fields.get("seconds", fields.get("cell_backlog_s", 0.0))))
        write(self, kind, **fields)

    return record


RunLog.write = _recording(RunLog.write)  # type: ignore[method-assign]


def cell_ran_behind() -> bool:
    """Whether a simulated cell of the test being run ran further behind the clock than `mrguide sim2real` judges
    (MAX_CELL_BACKLOG_S): a run that was not a real-time one, on a machine too busy for it (the CI's is at times)."""
    return any(s > MAX_CELL_BACKLOG_S for s in _backlogs)


def pytest_runtest_setup(item: pytest.Item) -> None:
    _backlogs.clear()  # each test judged on its own cells


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(
    item: pytest.Item, call: pytest.CallInfo
) -> Generator[None, pytest.TestReport, pytest.TestReport]:
    """A failure while a simulated cell of the test ran behind the clock says so in the report's properties (which
    reach the controller from an xdist worker)."""
    report = yield
    if report.failed and cell_ran_behind():
        report.user_properties.append(("cell_behind_the_clock", True))
    return report


def pytest_runtest_logreport(report: pytest.TestReport) -> None:
    """Every failure, in the controller, listed in $MRGUIDE_FAILED_REALTIME (`FAILED_REALTIME`): "behind" only with
    the report's word for it, so that a worker's crash, which has none, counts as a failure on time."""
    listed = os.environ.get(FAILED_REALTIME)
    if listed and report.failed and "PYTEST_XDIST_WORKER" not in os.environ:  # the controller lists, not a worker
        behind = ("cell_behind_the_clock", True) in report.user_properties
        with open(listed, "a") as fh:
            fh.write(f"{'behind' if behind else 'on-time'} {report.nodeid}\n")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        path = item.path.relative_to(config.rootpath).as_posix()
        if path.startswith(REALTIME) and not path.startswith(COMPUTE_ONLY):
            item.add_marker(pytest.mark.realtime)


@dataclass
class CliRun:
    """Exit code (argparse's SystemExit included) and output of one `mrguide` command."""

    code: int
    out: str
    err: str

    def assert_refused(self, *words: str) -> str:
        """Exit 2, no traceback, and one line on stderr naming each of `words` (argparse may print its usage
        lines before it). Returns that line."""
        assert self.code == 2, (self.code, self.err)
        assert "Traceback" not in self.err and "Traceback" not in self.out
        lines = self.err.strip().splitlines()
        assert lines, "nothing on stderr"
        usage = lines[:-1]
        if usage:  # argparse: "usage: mrguide ..." (wrapped lines indented), then "mrguide ...: error: ..."
            assert usage[0].startswith("usage: ") and all(line.startswith(" ") for line in usage[1:]), lines
            assert ": error: argument " in lines[-1], lines
        assert lines[-1].startswith("mrguide "), lines
        for word in words:
            assert word in lines[-1], (word, lines[-1])
        return lines[-1]


@pytest.fixture
def run_cli(capsys):
    """run_cli(argv) -> CliRun: `mrguide.cli.main(argv)` in-process."""
    from mrguide.cli import main

    def run(argv: list) -> CliRun:
        try:
            code = main([str(a) for a in argv])
        except SystemExit as exc:
            code = exc.code
        out, err = capsys.readouterr()
        return CliRun(code, out, err)

    return run


@pytest.fixture
def policy_file():
    """policy_file(path, metadata=None, arrays=None, drop=(), **changes) -> path: a valid one-layer policy file
    (zero weights: the target on the phase's anchor, a finite action everywhere, decision period 0.1 s) with
    `changes` to its metadata and the keys in `drop` removed, or `metadata` replacing it whole, and `arrays`
    replacing layer arrays."""
    from mrguide.config import to_dict
    from mrguide.deploy.policy import FORMAT, FORMAT_VERSION, HEAD_KIND
    from mrguide.robot import load_robot
    from mrguide.task import ACT_DIM, ACT_LAYOUT, OBS_DIM, OBS_LAYOUT, TaskConfig

    good = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "obs_layout": list(OBS_LAYOUT),
        "act_layout": list(ACT_LAYOUT),
        "activations": ["tanh"],
        "workspace": {"low": list(load_robot().workspace.low), "high": list(load_robot().workspace.high)},
        "task": to_dict(TaskConfig()),
        "decision_period": 0.1,
        "head": {"kind": HEAD_KIND, "max_offset": 0.5, "carry_progress": 0.5},
    }

    def write(path: Path, metadata: Any = None, arrays: dict | None = None, drop: tuple = (), **changes: Any) -> Path:
        meta = metadata if metadata is not None else {k: v for k, v in {**good, **changes}.items() if k not in drop}
        layers = {
            "W0": np.zeros((ACT_DIM, OBS_DIM)),
            "b0": np.zeros(ACT_DIM),
            "W0_carry": np.zeros((ACT_DIM, OBS_DIM)),
            "b0_carry": np.zeros(ACT_DIM),
            **(arrays or {}),
        }
        np.savez(path, metadata=np.array(json.dumps(meta)), **layers)
        return path

    return write


def build_wheel(dest: Path) -> Path:
    """The wheel of this checkout, as `pip install .` builds it (the annotation page's scripts included), built
    into `dest` by the running interpreter without build isolation (no download of setuptools). One build at a
    time: pip builds in the checkout (its build/ and egg-info), and two pytest-xdist workers building at once
    broke each other's build."""
    with open(Path(tempfile.gettempdir()) / "mrguide-wheel-build.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        return _build_wheel(dest)


def _build_wheel(dest: Path) -> Path:
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(dest),
            str(Path(__file__).resolve().parents[1]),
        ],
        check=True,
        capture_output=True,
        timeout=300,
    )
    (wheel,) = dest.glob("mrguide-*.whl")
    return wheel


def render_calibration_images(client: int, tmp_path: Path) -> Path:
    """Twin renders of the default board from the first three default views, as a person would take them with the
    HMD: PNGs in tmp_path/images, with the intrinsics (k.json) and head poses (poses.json) beside them."""
    import cv2

    from mrguide.calibration.config import CalibrationConfig
    from mrguide.twin.camera import look_at
    from mrguide.twin.markers import TwinCalibrationConfig, TwinHmd, add_targets

    twin = TwinCalibrationConfig()
    add_targets(client, CalibrationConfig())
    hmd = TwinHmd(client, twin.T_base_hmd, np.eye(4))
    folder = tmp_path / "images"
    folder.mkdir()
    poses = {}
    for i, eye in enumerate(twin.views[:3]):
        hmd.move_to(look_at(np.array(eye), np.array(twin.look_at), np.array([0, 0, 1.0])))
        frame = hmd.frame()
        cv2.imwrite(str(folder / f"view{i}.png"), cv2.cvtColor(frame.image, cv2.COLOR_RGB2BGR))
        poses[f"view{i}.png"] = frame.T_hmd_cam.tolist()
    (tmp_path / "poses.json").write_text(json.dumps(poses))
    (tmp_path / "k.json").write_text(json.dumps(hmd.camera_model.to_dict()))
    return folder
