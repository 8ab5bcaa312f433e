"""Experiments are registered where they are defined: a new one needs no edit of the CLI."""

from dataclasses import dataclass
from pathlib import Path

import pytest

from mrguide.experiments import registry
from mrguide.experiments.train_runs import TrainRun


@dataclass(frozen=True)
class ToyConfig:
    seeds: int = 1
    steps: int = 10
    config: str = ""


def _toy_runs(cfg: ToyConfig, base: str | None) -> list[TrainRun]:
    return [TrainRun(name=f"seed{s}", seed=s, steps=cfg.steps, guided=False, config=base) for s in range(cfg.seeds)]


def _toy_report(cfg: ToyConfig, base: str | None, root: Path, episodes: int) -> dict[str, bytes]:
    return {"summary.md": f"toy: {cfg.seeds} seeds of {cfg.steps} steps in {root.name}\n".encode()}


@pytest.fixture
def toy(tmp_path):
    (tmp_path / "toy.toml").write_text("[experiment]\nseeds = 2\nsteps = 30\n")
    registry.register("toy", registry.Experiment(ToyConfig, "toy.toml", "runs/toy", _toy_runs, _toy_report, "a toy"))
    yield tmp_path / "toy.toml"
    registry._REGISTRY.pop("toy")


def test_a_registered_experiment_is_a_command_and_reports_from_its_run_directories(toy, tmp_path, run_cli):
    assert "toy" in run_cli(["experiment", "--help"]).out
    out = tmp_path / "runs"
    for s in range(2):
        (out / f"seed{s}").mkdir(parents=True)
        (out / f"seed{s}" / "done").touch()
    res = run_cli(["experiment", "report", "toy", "--config", toy, "--out", out])
    assert res.code == 0, res.err
    assert "toy: 2 seeds of 30 steps in runs" in res.out
    assert (out / "summary.md").read_text().startswith("toy: 2 seeds")


def test_a_report_of_unfinished_runs_is_refused(toy, tmp_path, run_cli):
    res = run_cli(["experiment", "report", "toy", "--config", toy, "--out", tmp_path / "none"])
    assert res.code != 0 and "2 runs are not finished" in res.err


def test_a_name_is_registered_once_and_must_be_a_command_word():
    exp = registry.experiments()["person"]
    with pytest.raises(ValueError, match="registered already"):
        registry.register("person", exp)
    for bad in ("", "report", "two words", "a/b"):
        with pytest.raises(ValueError, match="letters, digits"):
            registry.register(bad, exp)
