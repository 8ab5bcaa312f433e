"""Every experiment by name: each experiment module registers its own (`register`, at the end of the module), and
`experiments()` gives them all to the CLI (`mrguide experiment NAME`, `mrguide experiment report NAME`).

`EXPERIMENT_MODULES` names the modules of this package that hold experiments; they are light to import (no PyBullet,
torch or matplotlib until a run or a report needs them), so the parser can list every experiment. A package of
its own can register more before `mrguide.cli.main` builds the parser.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

#: The modules of mrguide.experiments that register experiments, in the order `mrguide experiment --help` lists them.
EXPERIMENT_MODULES = (
    "learning_curves",
    "noise_robustness",
    "generalization",
    "person",
    "parts",
    "peers",
    "sim2real_runs",
)


@dataclass(frozen=True)
class Experiment:
    """How to run and report one experiment: its config class and file, its runs, an optional evaluation of
    the trained runs (Ray tasks), and its report built from the run directories."""

    config_cls: type[Any]
    default_config: str  # file name under configs/experiments/
    default_out: str
    runs: Callable[[Any, str | None], list]
    report: Callable[[Any, str | None, Path, int], dict[str, bytes]]
    help: str = ""  # one line for `mrguide experiment --help`
    #: Ray tasks evaluating each trained run (run, root, cfg) → the file that marks it evaluated
    evaluate: Callable[..., str] | None = None
    evaluated: Callable[[Any, Path], Path] | None = None  # (run, root) → that file


_REGISTRY: dict[str, Experiment] = {}


def register(name: str, experiment: Experiment) -> Experiment:
    """Make `experiment` `mrguide experiment NAME`; ValueError if the name is taken or not a command word."""
    if not name or name == "report" or not all(c.isalnum() or c == "-" for c in name):
        raise ValueError(f"experiment name {name!r}: letters, digits and '-' only, and not 'report'")
    if name in _REGISTRY:
        raise ValueError(f"experiment {name!r} is registered already")
    _REGISTRY[name] = experiment
    return experiment


def experiments() -> dict[str, Experiment]:
    """Every registered experiment, by name: the modules of `EXPERIMENT_MODULES` first, then any registered later."""
    modules = [f"mrguide.experiments.{m}" for m in EXPERIMENT_MODULES]
    for module in modules:
        importlib.import_module(module)
    rank = {m: i for i, m in enumerate(modules)}  # in module order whichever was imported first; stable within one
    return dict(sorted(_REGISTRY.items(), key=lambda item: rank.get(item[1].runs.__module__, len(rank))))
