"""The training configs shipped in configs/runs/ load, and configs/runs/person.toml is the person it describes."""

from pathlib import Path

import pytest

from mrguide.policies.train_config import RunConfig
from tests import shipped_files

ROOT = Path(__file__).resolve().parents[2]
TRAIN_CONFIGS = shipped_files.RUN_CONFIGS


def test_the_training_configs_are_found():
    assert {"person.toml", "live_parity.toml", "sac.toml", "ur10_run.toml"} <= {p.name for p in TRAIN_CONFIGS}


@pytest.mark.parametrize("path", TRAIN_CONFIGS, ids=lambda p: p.name)
def test_each_training_config_loads(path):
    RunConfig.load(path)


def test_the_person_config_is_a_headset_user_marking_without_ground_truth():
    guidance = RunConfig.load(ROOT / "configs" / "runs" / "person.toml").guidance
    n = guidance.noise
    assert (n.bias_sigma, n.sigma_across, n.sigma_along, n.outlier_rate) == (0.007, 0.01, 0.02, 0.03)
    assert n.sigma == 0.0 and guidance.reference == "running_median"
