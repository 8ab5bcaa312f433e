"""The training configs shipped in configs/ load, and configs/person.toml is the person its comment describes."""

import tomllib
from pathlib import Path

import pytest

from mrguide.experiments.runs import SECTIONS
from mrguide.policies.train import load_sac_config, load_train_config

ROOT = Path(__file__).resolve().parents[2]
TRAIN_CONFIGS = sorted(
    p for p in (ROOT / "configs").glob("*.toml") if set(tomllib.loads(p.read_text())) <= set(SECTIONS)
)


def test_the_training_configs_are_found():
    assert {"person.toml", "live_parity.toml"} <= {p.name for p in TRAIN_CONFIGS}


@pytest.mark.parametrize("path", TRAIN_CONFIGS, ids=lambda p: p.name)
def test_each_training_config_loads(path):
    load_train_config(path)
    load_sac_config(path)


def test_the_person_config_is_a_headset_user_marking_without_ground_truth():
    _, _, guidance, _ = load_train_config(ROOT / "configs" / "person.toml")
    n = guidance.noise
    assert (n.bias_sigma, n.sigma_across, n.sigma_along, n.outlier_rate) == (0.007, 0.01, 0.02, 0.03)
    assert n.sigma == 0.0 and guidance.reference == "running_median"
