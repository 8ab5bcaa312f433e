"""Every shipped experiment file loads, and every run it describes has a valid training configuration
(the check `mrguide experiment` makes before it starts anything)."""

import argparse
from pathlib import Path

import pytest

from mrguide.config import ConfigError
from mrguide.experiments.commands import _setup
from mrguide.experiments.registry import experiments
from tests import shipped_files

ROOT = Path(__file__).resolve().parents[2]
FILES = shipped_files.EXPERIMENT_FILES


def experiment_of(path: Path) -> str:
    """The experiment a shipped file belongs to: the longest experiment name its file name starts with."""
    return max((n for n in experiments() if path.stem.startswith(n.replace("-", "_"))), key=len)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name)
def test_shipped_experiment_file_sets_up_every_run(path):
    args = argparse.Namespace(name=experiment_of(path), config=str(path), seeds=None, steps=None, out=None)
    _, cfg, _, _ = _setup(args)
    assert cfg.seeds >= 1


def test_a_file_with_a_bad_override_is_refused_before_anything_runs(tmp_path):
    bad = tmp_path / "gen.toml"
    bad.write_text(
        (ROOT / "configs/experiments/generalization.toml").read_text()
        + '\n[experiment.overrides]\n"guidance.marks" = "pick_plase"\n'
    )
    with pytest.raises(ConfigError, match="pick_plase"):
        _setup(argparse.Namespace(name="generalization", config=str(bad), seeds=None, steps=None, out=None))


def test_every_registered_experiment_has_its_shipped_file():
    for name, exp in experiments().items():
        assert (ROOT / "configs/experiments" / exp.default_config).is_file(), name
