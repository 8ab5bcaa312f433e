"""The training configs shipped in configs/ load, and configs/anchor_offset.toml sets what its comment says."""

import tomllib
from pathlib import Path

import pytest

from mrguide.experiments.runs import SECTIONS
from mrguide.policies.train import load_train_config

ROOT = Path(__file__).resolve().parents[2]
TRAIN_CONFIGS = sorted(p for p in (ROOT / "configs").glob("*.toml") if set(tomllib.loads(p.read_text())) <= set(SECTIONS))


def test_the_training_configs_are_found():
    assert {"anchor_offset.toml", "experiment_td3.toml", "action_noise_0.05.toml"} <= {p.name for p in TRAIN_CONFIGS}


@pytest.mark.parametrize("path", TRAIN_CONFIGS, ids=lambda p: p.name)
def test_each_training_config_loads(path):
    load_train_config(path)


def test_anchor_offset_config_sets_the_three_options():
    _, ddpg, guidance, _ = load_train_config(ROOT / "configs" / "anchor_offset.toml")
    assert (ddpg.actor_head, ddpg.act_with_target, guidance.action_noise_clip) == ("anchor_offset", True, False)
