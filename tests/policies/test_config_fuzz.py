"""Property-based fuzz (Hypothesis) of the training configs: any TOML-like input gives a valid config or a
ConfigError — never another exception, never a config holding NaN/inf."""

from __future__ import annotations

import dataclasses
import math
import typing

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mrguide.config import ConfigError, from_dict
from mrguide.policies.ddpg import DDPGConfig
from mrguide.policies.guidance import GuidanceConfig
from mrguide.policies.train_config import TrainConfig
from mrguide.task import TaskConfig
from mrguide.twin.config import TwinConfig

SCALARS = (
    st.none()
    | st.booleans()
    | st.integers(-(10**12), 10**12)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8)
)
VALUES = st.recursive(
    SCALARS,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=4),
    max_leaves=12,
)


def field_values(cls) -> st.SearchStrategy[dict]:
    """Tables over the real field names of `cls` (nested tables for nested configs, a stray key now and
    then) with arbitrary values."""
    hints = typing.get_type_hints(cls)
    parts = {
        f.name: (field_values(hints[f.name]) | VALUES) if dataclasses.is_dataclass(hints[f.name]) else VALUES
        for f in dataclasses.fields(cls)
    }
    return st.fixed_dictionaries({}, optional={**parts, "not_a_key": VALUES})


def numbers(obj) -> list[float]:
    out = []
    for f in dataclasses.fields(obj):
        v = getattr(obj, f.name)
        if dataclasses.is_dataclass(v):
            out += numbers(v)
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            out.append(v)
        elif isinstance(v, tuple):
            out += [x for x in v if isinstance(x, (int, float))]
    return out


@pytest.mark.parametrize("cls", [TrainConfig, DDPGConfig, GuidanceConfig, TaskConfig, TwinConfig])
def test_config_loader_gives_a_finite_config_or_a_config_error(cls):
    @settings(max_examples=150, deadline=None)
    @given(field_values(cls))
    def check(data):
        try:
            cfg = from_dict(cls, data, "fuzz.toml [x]")
        except ConfigError as exc:
            assert str(exc).startswith("fuzz.toml [x]: ")
            return
        assert all(math.isfinite(v) for v in numbers(cfg))

    check()
