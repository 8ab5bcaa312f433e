"""`deploy.pose_source = "hmd"`: a dry run sees the part through the cell's simulated headset (latency, lost frames,
its calibration draw), as sim2real's HMD conditions do; on the robot it is refused (no headset streams poses yet)."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pytest

from mrguide.cli import main
from mrguide.config import ConfigError
from mrguide.deploy.commands import _pose_feed
from mrguide.deploy.runlog import read_log
from mrguide.deploy.session import DeployConfig
from mrguide.task import OBS_OBJECT, TaskConfig

ROOT = Path(__file__).parents[2]
POLICY = ROOT / "docs" / "results" / "cup" / "main5k" / "policy.npz"


def test_a_dry_run_acts_on_the_headsets_poses(tmp_path):
    log = tmp_path / "hmd.jsonl"
    args = ["deploy", "--dry-run", "--config", str(ROOT / "configs" / "cells" / "real_cell.toml"), "--quiet"]
    args += ["--policy", str(POLICY), "--set", "deploy.pose_source=hmd", "--episodes", "1", "--log", str(log)]
    assert main(args) == 0
    records = read_log(log)
    (hmd,) = [r for r in records if r["kind"] == "hmd"]
    assert hmd["frames"] >= 1
    seen = [r for r in records if r["kind"] == "decision" and r.get("object_from") == "source"]
    errors = [np.linalg.norm(np.subtract(np.asarray(r["obs"])[OBS_OBJECT], r["pose"]["true"])[:2]) for r in seen]
    assert errors and 0.0 < np.median(errors) < 0.02  # the part where the headset sees it: millimetres off
    assert min(r["pose"]["age_s"] for r in seen) >= 0.1  # never younger than the real cell's 0.1 s latency


def test_the_headset_source_is_refused_on_the_robot():
    args = argparse.Namespace(config=None)
    with pytest.raises(ConfigError, match="only with --dry-run"):
        _pose_feed(args, DeployConfig(pose_source="hmd"), TaskConfig(), 0, None)
