"""An expert source is registered where it is defined: `guidance.source = NAME` then trains with it, with no edit of
the config, the trainer or the CLI."""

from __future__ import annotations

import dataclasses

import pytest

from mrguide.config import ConfigError
from mrguide.policies import guided_expert
from mrguide.policies.choices import EXPERT_SOURCES
from mrguide.policies.experts import OracleExpert
from mrguide.policies.guidance import GuidanceConfig
from mrguide.policies.train import Trainer
from tests.run_configs import run_config, sections


class CountingOracle(OracleExpert):
    """The scripted oracle, counting what it was asked."""

    asked = 0

    def annotate(self, obs, previous=None):
        CountingOracle.asked += 1
        return super().annotate(obs, previous)


@pytest.fixture
def toy_source():
    guided_expert.register_expert_source("toy-oracle", lambda g, env, seed: CountingOracle(env.task_cfg))
    CountingOracle.asked = 0
    yield "toy-oracle"
    del guided_expert.IN_PROCESS_SOURCES["toy-oracle"]
    EXPERT_SOURCES.remove("toy-oracle")


def test_a_registered_source_answers_the_marks_of_a_training_run(toy_source, tmp_path):
    tc, dc, gc, ec = sections()
    tc = dataclasses.replace(tc, total_steps=300, learning_starts=64, batch_size=32, eval_every=10_000)
    tr = Trainer(
        run_config(tc, dataclasses.replace(dc, hidden=(16, 16)), dataclasses.replace(gc, source=toy_source), ec),
        tmp_path,
    )
    try:
        tr.run(stop_at=200)
    finally:
        tr.close()
    assert CountingOracle.asked == tr.counters.asked > 0
    assert (tmp_path / "annotations.jsonl").read_text().count("\n") == tr.counters.asked


def test_a_source_nobody_registered_is_refused_and_a_name_is_registered_once():
    with pytest.raises(ConfigError, match=r"guidance\.source must be"):
        GuidanceConfig(source="toy-oracle")
    for taken in ("oracle", "live"):
        with pytest.raises(ValueError, match="registered already"):
            guided_expert.register_expert_source(taken, lambda g, env, seed: None)
