"""Ranges declared with the fields (`Annotated[float, Range(lo, hi)]`): every default lies in its range, and a
value outside it is refused with the field named, whether the config is built in code or read through `--set`
style overrides."""

from __future__ import annotations

import dataclasses
import importlib
import pkgutil

import pytest

import mrguide
from mrguide.config import ConfigError, Range, _ranged_fields, replace_path


def declares_a_range(cls: type) -> bool:
    """A field annotation of `cls` itself names a Range (read as text: some hints resolve only for type checkers)."""
    return any("Range(" in str(a) for a in vars(cls).get("__annotations__", {}).values())


def ranged_configs() -> list[type]:
    """Every dataclass of the package (the modules this install can import) with at least one declared Range."""
    found: dict[str, type] = {}
    for info in pkgutil.walk_packages(mrguide.__path__, "mrguide."):
        try:
            module = importlib.import_module(info.name)
        except ImportError:  # an optional extra (mujoco, rerun, ...) this install lacks
            continue
        for obj in vars(module).values():
            if (
                isinstance(obj, type)
                and dataclasses.is_dataclass(obj)
                and obj.__module__ == info.name
                and declares_a_range(obj)
            ):
                found[f"{obj.__module__}.{obj.__qualname__}"] = obj
    return [found[k] for k in sorted(found)]


def default_instance(cls: type) -> object | None:
    try:
        return cls()
    except TypeError:  # required fields (a marker's placement): no default instance to probe
        return None


CONFIGS = ranged_configs()
DEFAULTS = {c: d for c in CONFIGS if (d := default_instance(c)) is not None}


def test_the_ranges_are_declared_across_the_package() -> None:
    assert len(CONFIGS) >= 30 and len(DEFAULTS) >= len(CONFIGS) - 2
    assert sum(len(_ranged_fields(c)) for c in CONFIGS) >= 120


@pytest.mark.parametrize("cls", list(DEFAULTS), ids=lambda c: c.__qualname__)
def test_defaults_lie_in_their_ranges_and_outside_values_are_refused(cls: type) -> None:
    default = DEFAULTS[cls]
    for name, r, integer in _ranged_fields(cls):
        value = getattr(default, name)
        assert value is None or r.low <= value <= r.high, (
            f"{cls.__qualname__}.{name} = {value} outside [{r.low}, {r.high}]"
        )
        assert isinstance(value, int) or not integer
        step = 1 if integer else max(1.0, abs(r.high))
        for bad in (r.high + step, r.low - step, 0.5 if integer and r.low <= 0.5 <= r.high else None):
            if bad is None:
                continue
            with pytest.raises(ConfigError, match=rf"\.{name} = "):
                dataclasses.replace(default, **{name: bad})


def test_an_override_out_of_range_names_the_key_and_the_range() -> None:
    from mrguide.policies.ddpg import DDPGConfig

    with pytest.raises(ConfigError, match=r"ddpg\.tau = 2\.0: expected a finite number in \[1e-06, 1\]"):
        replace_path(DDPGConfig(), "tau", 2)
    assert replace_path(DDPGConfig(), "tau", 0.01).tau == 0.01


def test_an_integer_field_refuses_a_fraction_and_a_unit_ends_the_message() -> None:
    from mrguide.twin.config import RealityGap

    with pytest.raises(ConfigError, match=r"reality_gap\.actuator_latency = 1\.5: expected an integer"):
        RealityGap(actuator_latency=1.5)  # type: ignore[arg-type]
    with pytest.raises(ConfigError, match=r"reality_gap\.object_mass = 20\.0: .* kg"):
        RealityGap(object_mass=20.0)
    assert Range(0, 1).unit == ""
