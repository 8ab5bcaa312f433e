"""`mrguide deploy` and the sim-to-real cells read a config file once, every section from that one parse."""

from __future__ import annotations

from pathlib import Path

import pytest

import mrguide.config as config_module
from mrguide.cli import main

ROOT = Path(__file__).parents[2]
REAL = ROOT / "configs" / "cells" / "real_cell.toml"
POLICY = ROOT / "docs" / "results" / "cup" / "main5k" / "policy.npz"


class _Built(Exception):
    """Raised by the dry run's factory once it has the parsed file: the run stops before anything starts."""


@pytest.fixture
def reads(monkeypatch) -> list[str]:
    seen: list[str] = []
    real = config_module.load_toml
    monkeypatch.setattr(config_module, "load_toml", lambda path: seen.append(str(path)) or real(path))
    return seen


def test_deploy_reads_its_config_once_and_hands_the_parse_to_the_dry_run(reads, monkeypatch):
    from mrguide.cell.commands import CellDryRun

    given = []

    def built(self, config):
        given.append(config)
        raise _Built

    monkeypatch.setattr(CellDryRun, "__init__", built)
    with pytest.raises(_Built):
        main(["deploy", "--dry-run", "--policy", str(POLICY), "--config", str(REAL), "--episodes", "1"])
    assert reads.count(str(REAL)) == 1 and given[0].path == REAL


def test_a_sim_to_real_cell_is_read_once(reads):
    from mrguide.experiments.sim2real import load_real_cell

    cell = load_real_cell(REAL)
    assert reads.count(str(REAL)) == 1 and cell.env.twin.reality_gap.object_mass == 0.30
