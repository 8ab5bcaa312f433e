"""Tests build a training run's root config from its sections, as the tests before the root took them apart."""

from __future__ import annotations

import dataclasses
from typing import Any

from mrguide.policies.train_config import RunConfig

#: Evaluation episodes of a test's training run: at the default 10 a short test run's final evaluation plays up to
#: 600 decisions (10 x the 60-decision horizon), as many as a 600-step test run trains, and no test built from these
#: sections judges a policy by its evaluations' rate.
TEST_EVAL_EPISODES = 2


def sections() -> tuple[Any, Any, Any, Any]:
    """(train, ddpg, guidance, env) at their defaults, but `TEST_EVAL_EPISODES` evaluation episodes."""
    run = RunConfig()
    return dataclasses.replace(run.train, eval_episodes=TEST_EVAL_EPISODES), run.learners["ddpg"], run.guidance, run.env


def run_config(tc: Any, dc: Any, gc: Any, ec: Any, **learners: Any) -> RunConfig:
    """The root of these sections (`learners`: other learners' sections by name, e.g. sac=...)."""
    return RunConfig(tc, gc, ec, {**RunConfig().learners, "ddpg": dc, **learners})
