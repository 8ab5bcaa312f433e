"""Tests build a training run's root config from its sections, as the tests before the root took them apart."""

from __future__ import annotations

from typing import Any

from mrguide.policies.train_config import RunConfig


def sections() -> tuple[Any, Any, Any, Any]:
    """(train, ddpg, guidance, env) at their defaults."""
    run = RunConfig()
    return run.train, run.learners["ddpg"], run.guidance, run.env


def run_config(tc: Any, dc: Any, gc: Any, ec: Any, **learners: Any) -> RunConfig:
    """The root of these sections (`learners`: other learners' sections by name, e.g. sac=...)."""
    return RunConfig(tc, gc, ec, {**RunConfig().learners, "ddpg": dc, **learners})
