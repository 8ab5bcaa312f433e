"""`mrguide experiment parts`: its runs (each part's config, the person's guidance, teaching or not) and its report,
rebuilt from the committed runs of docs/results/parts."""

from __future__ import annotations

from pathlib import Path

import pytest

from mrguide.config import ConfigError, load_section
from mrguide.experiments.parts import PartsConfig, parts_report, runs

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "docs" / "results" / "parts"


def test_each_part_trains_with_its_config_and_the_persons_guidance_teaching_or_not():
    cfg = PartsConfig(parts=("hole_plate", "keepout_block"), seeds=2, centre_prior_seeds=1)
    made = runs(cfg, str(ROOT / "configs" / "runs" / "person.toml"))
    assert [r.name for r in made] == [
        "hole_plate/taught/seed0",
        "hole_plate/taught/seed1",
        "hole_plate/centre_prior/seed0",
        "keepout_block/taught/seed0",
        "keepout_block/taught/seed1",
        "keepout_block/centre_prior/seed0",
    ]
    first = made[0]
    assert Path(first.config).name == "hole_plate.toml" and first.client == "bot"
    assert first.overrides["guidance.noise.sigma_along"] == 0.02 and first.overrides["guidance.pose.sigma"] == 0.003
    assert [r.overrides["guidance.noise.teaches"] for r in made[:3]] == [True, True, False]


def test_an_unknown_part_is_refused():
    with pytest.raises(ConfigError, match=r"experiment\.parts"):
        PartsConfig(parts=("plate",))


def test_the_committed_report_is_what_the_committed_runs_give():
    cfg = load_section(PartsConfig, RESULTS / "experiment.toml", "experiment", known=("experiment",))
    files = parts_report(cfg, None, RESULTS, 10)
    for name in ("summary.csv", "runs.csv"):
        assert files[name] == (RESULTS / name).read_bytes(), name
