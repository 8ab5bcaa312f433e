"""A policy whose weights are finite but whose output is not is refused at load, before any drive is enabled.

The crafted policies overflow (1e200 x 1e200 = inf, then inf - inf = NaN) only in part of the observation
space (one gripper state, or the later phases), so probing one observation would not find them.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mrguide.cli import main
from mrguide.config import to_dict
from mrguide.deploy.policy import FORMAT, FORMAT_VERSION, HEAD_KIND, ExportedPolicy, PolicyFileError
from mrguide.drivers.cobot import Cobot
from mrguide.robot import load_robot
from mrguide.task import ACT_LAYOUT, OBS_DIM, OBS_LAYOUT, TaskConfig

HUGE = 1e200
G, PHI = 3, 4  # observation indices of the gripper state and the task progress


def _write_policy(path: Path, layers: list[tuple[np.ndarray, np.ndarray]]) -> Path:
    meta = {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "obs_layout": list(OBS_LAYOUT),
        "act_layout": list(ACT_LAYOUT),
        "activations": ["relu"] * (len(layers) - 1) + ["tanh"],
        "workspace": {"low": list(load_robot().workspace.low), "high": list(load_robot().workspace.high)},
        "task": to_dict(TaskConfig()),
        "decision_period": 0.1,
        "head": {"kind": HEAD_KIND, "max_offset": 0.5, "carry_progress": 0.5},
    }
    arrays = {"metadata": np.array(json.dumps(meta))}
    for i, (W, b) in enumerate(layers):
        arrays[f"W{i}"], arrays[f"b{i}"] = W, b
    arrays["W0_carry"], arrays["b0_carry"] = layers[0]  # the same first layer in transport and release
    np.savez(path, **arrays)
    return path


def _overflowing_policy(path: Path, trigger: int, threshold: float) -> Path:
    """Output NaN where observation[trigger] > threshold, 0 elsewhere; every weight finite."""
    W0 = np.zeros((2, OBS_DIM))
    W0[:, trigger] = HUGE
    b0 = np.full(2, -HUGE * threshold)  # relu(1e200 (x - threshold)): 0 below, up to 1e200 above
    W1 = np.diag([HUGE, HUGE])  # 1e200 x 1e200 overflows to inf
    W2 = np.tile([1.0, -1.0], (4, 1))  # inf - inf = NaN, whatever the summation order
    return _write_policy(path, [(W0, b0), (W1, np.zeros(2)), (W2, np.zeros(4))])


@pytest.mark.parametrize("trigger, threshold, where", [(G, 0.0, "g = +1"), (PHI, 0.5, "phase 3")])
def test_policy_with_non_finite_output_somewhere_in_the_workspace_is_refused(tmp_path, trigger, threshold, where):
    path = _overflowing_policy(tmp_path / "overflow.npz", trigger, threshold)
    with pytest.raises(PolicyFileError) as info:
        ExportedPolicy.load(path, load_robot(), TaskConfig())
    message = str(info.value)
    assert str(path) in message and "non-finite" in message and where in message


def test_a_finite_policy_passes_the_probe(tmp_path):
    rng = np.random.default_rng(0)
    path = _write_policy(
        tmp_path / "ok.npz",
        [(rng.normal(size=(16, OBS_DIM)), rng.normal(size=16)), (rng.normal(size=(4, 16)), rng.normal(size=4))],
    )
    policy = ExportedPolicy.load(path, load_robot(), TaskConfig())
    assert np.all(np.isfinite(policy(np.zeros(OBS_DIM))))


def test_deploy_refuses_it_before_enabling_the_drives(tmp_path, monkeypatch, capsys):
    enabled = []
    monkeypatch.setattr(Cobot, "enable", lambda self, timeout=None: enabled.append(1))
    path = _overflowing_policy(tmp_path / "overflow.npz", G, 0.0)
    assert main(["deploy", "--policy", str(path), "--dry-run", "--episodes", "1", "--quiet"]) == 2
    assert "non-finite" in capsys.readouterr().err
    assert enabled == []


@pytest.mark.parametrize("edge, loads", [(0.05, True), (0.06, False)])
def test_a_policy_from_before_the_part_library_names_its_block_by_its_edge(tmp_path, edge, loads):
    """Files exported before `task.part` carry `object_height`; the block's 5 cm edge is today's "block"."""
    rng = np.random.default_rng(0)
    layers = [(rng.normal(size=(16, OBS_DIM)), rng.normal(size=16)), (rng.normal(size=(4, 16)), rng.normal(size=4))]
    path = _write_policy(tmp_path / "old.npz", layers)
    with np.load(path) as f:
        arrays = dict(f)
    meta = json.loads(str(arrays["metadata"]))
    del meta["task"]["part"]
    meta["task"]["object_height"] = edge
    arrays["metadata"] = np.array(json.dumps(meta))
    np.savez(path, **arrays)
    if loads:
        assert ExportedPolicy.load(path, load_robot(), TaskConfig()) is not None
    else:
        with pytest.raises(PolicyFileError, match="task parameters differ from the configuration: part"):
            ExportedPolicy.load(path, load_robot(), TaskConfig())
