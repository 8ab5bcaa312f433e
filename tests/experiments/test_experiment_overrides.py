"""`mrguide experiment NAME --set`: a training key for every run; a run is never resumed into another configuration."""

import argparse
import dataclasses
import json

import pytest

from mrguide.config import ConfigError
from mrguide.experiments import noise_robustness
from mrguide.experiments.commands import _setup
from mrguide.experiments.train_runs import TrainRun, check_same_config, run_config, run_record


def _args(**kw):
    return argparse.Namespace(
        **{"name": "person", "config": None, "seeds": 2, "steps": 100, "out": None, "set": []} | kw
    )


def test_set_reaches_every_run_over_the_files_overrides_and_the_swept_key_stays_the_experiments():
    sets = [("ddpg.lr_actor", 0.001), ("guidance.noise.sigma", 0.5)]
    _, cfg, base, _ = _setup(_args(name="noise-robustness", seeds=1, set=sets))
    runs = noise_robustness.runs(cfg, base)
    assert len(runs) == len(cfg.sigmas)
    for run, sigma in zip(runs, cfg.sigmas):
        cfg = run_config(run)
        ddpg, guidance = cfg.learners["ddpg"], cfg.guidance
        assert ddpg.lr_actor == 0.001
        assert guidance.noise.sigma == sigma  # what the experiment varies is set last
        assert guidance.pose.sigma == 0.003  # the file's own overrides stay


def test_a_bad_set_is_refused_before_anything_runs():
    with pytest.raises(ConfigError, match="lr_actr"):
        _setup(_args(set=[("ddpg.lr_actr", 0.001)]))
    with pytest.raises(ConfigError, match="lr_actor"):
        _setup(_args(set=[("ddpg.lr_actor", -1.0)]))


def _done(run: TrainRun, root, record: dict) -> None:
    out = run.directory(root)
    out.mkdir(parents=True)
    (out / "run.json").write_text(json.dumps(record))
    (out / "done").write_text("{}")


def test_a_run_made_with_another_configuration_is_not_resumed_into_this_one(tmp_path):
    run = TrainRun("seed0", 0, 100, True, None, {"ddpg.lr_actor": 0.001})
    _done(run, tmp_path, run_record(run))
    check_same_config(run, tmp_path)  # the same configuration: resumed (here: done, skipped)
    changed = dataclasses.replace(run, overrides={"ddpg.lr_actor": 0.002})
    with pytest.raises(ConfigError, match=r"ddpg\.lr_actor: 0\.001 → 0\.002"):
        check_same_config(changed, tmp_path)


def test_a_field_the_code_gained_since_is_no_difference(tmp_path):
    run = TrainRun("seed0", 0, 100, True)
    record = run_record(run)
    del record["effective_config"]["ddpg"]["bc_weight"]  # as if written before the field existed
    _done(run, tmp_path, record)
    check_same_config(run, tmp_path)
    check_same_config(TrainRun("seed1", 1, 100, True), tmp_path)  # nothing there yet
