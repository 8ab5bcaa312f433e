"""Property-based fuzz (Hypothesis) of the config loaders and the numeric CLI options of deploy, drivers,
calibration and the sim-to-real commands.

Configs: tables of random keys and values (NaN, inf, huge, negative, strings, lists, nested tables), biased
toward each dataclass's own field names so the checks behind them are reached. `from_dict` must return a
config whose numbers are all finite, or raise ConfigError: nothing else.

CLI: random numeric strings for every numeric option: argparse exits with 2, or the parsed value meets
the option's constraint.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import math
import typing

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from mrguide.calibration.config import (
    BoardConfig,
    CalibrationConfig,
    DetectorConfig,
    HmdNoiseConfig,
    MarkerPlacement,
    RegistrationConfig,
    TargetsConfig,
)
from mrguide.cli import build_parser
from mrguide.config import ConfigError, from_dict
from mrguide.deploy.safety import SafetyConfig
from mrguide.deploy.session import DeployConfig
from mrguide.drivers.config import (
    BusConfig,
    CobotBusConfig,
    DriveConfig,
    JointDriveConfig,
    LimitOverrides,
    MasterConfig,
    TimingConfig,
    VacuumNodeConfig,
    resolve_limits,
)
from mrguide.robot import ArmConfig, RobotConfig, UrdfSource, Workspace, load_robot
from mrguide.twin.camera import CameraConfig, Intrinsics
from mrguide.twin.markers import TwinCalibrationConfig

FUZZ = settings(max_examples=120, deadline=None, suppress_health_check=[HealthCheck.too_slow])

SPECIAL_NUMBERS = [math.nan, math.inf, -math.inf, 0, -1, 1, 0.5, -0.5, 1e308, -1e308, 2**63, -(2**63), 2**70, 1e-300]
#: Strings that some field somewhere accepts, so a string field is sometimes valid and sometimes crossed over.
KNOWN_STRINGS = [
    "virtual",
    "socketcan",
    "pcan",
    "kvaser",
    "slcan",
    "etas",
    "mrguide",
    "can0",
    "cia402_drive.eds",
    "vacuum_generator.eds",
    "nope.eds",
    "grid",
    "charuco",
    "edges",
    "subpix",
    "DICT_4X4_50",
    "DICT_9X9_7",
    "runs/deploy",
    "",
    "nan",
    "1",
]
SCALARS = st.one_of(
    st.none(), st.booleans(), st.integers(), st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8)
)
GARBAGE = st.recursive(
    SCALARS,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=6), inner, max_size=3),
    max_leaves=8,
)


def _number(default: typing.Any, integer: bool) -> st.SearchStrategy:
    """Numbers for a field: its default, values near it (within 3x), extremes, anything."""
    known = isinstance(default, (int, float)) and not isinstance(default, bool) and math.isfinite(default)
    scale = abs(default) if known and default else 50.0  # no default: a required id or a coordinate
    near = (
        st.integers(-int(3 * scale) - 3, int(3 * scale) + 3)
        if integer
        else st.floats(-3 * scale, 3 * scale, allow_nan=False)
    )
    extreme = st.sampled_from(SPECIAL_NUMBERS) | st.integers() | st.floats()
    return _weighted((3, st.just(default) if known else near), (4, near), (3, extreme))


def _weighted(*choices: tuple[int, st.SearchStrategy]) -> st.SearchStrategy:
    """One of the strategies, picked with the given weights (st.one_of picks its branches about evenly)."""
    table = [strategy for weight, strategy in choices for _ in range(weight)]
    return st.integers(0, len(table) - 1).flatmap(lambda i: table[i])


def _value(hint: typing.Any, default: typing.Any) -> st.SearchStrategy:
    """Values for a field of type `hint`: mostly of that type (its default, near it, or extreme), sometimes garbage."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if dataclasses.is_dataclass(hint):
        plausible = _table(hint)
    elif hint is bool:
        plausible = st.booleans()
    elif hint in (int, float):
        plausible = _number(default, hint is int)
    elif hint is str:
        plausible = st.sampled_from(KNOWN_STRINGS + ([default] * 3 if isinstance(default, str) else [])) | st.text(
            max_size=10
        )
    elif origin is tuple:
        items = [_value(a, d) for a, d in zip(args, default or [None] * len(args)) if a is not Ellipsis] or [GARBAGE]
        if Ellipsis in args:
            items = [_value(args[0], None)]
        plausible = (
            st.lists(items[0], max_size=5)
            if Ellipsis in args
            else st.tuples(*items).map(list) | st.lists(items[0], max_size=len(items) + 1)
        )
    elif origin is dict:
        plausible = st.dictionaries(
            st.sampled_from(["receive_own_messages", "rx_queue_size", "tty_baudrate"]) | st.text(max_size=8),
            SCALARS,
            max_size=3,
        )
    else:
        plausible = GARBAGE
    return _weighted((9, plausible), (1, GARBAGE))


def _table(cls: type) -> st.SearchStrategy:
    """Dicts for dataclass `cls`: any subset of its fields (required ones mostly present), sometimes an unknown key."""
    hints = typing.get_type_hints(cls)
    required, optional = {}, {}
    for f in dataclasses.fields(cls):
        if f.default is not dataclasses.MISSING:
            optional[f.name] = _value(hints[f.name], f.default)
        elif f.default_factory is not dataclasses.MISSING:
            optional[f.name] = _value(hints[f.name], f.default_factory())
        else:
            required[f.name] = _value(hints[f.name], None)
    complete = st.fixed_dictionaries(required, optional=optional)
    partial = st.fixed_dictionaries({}, optional={**required, **optional})
    unknown = st.dictionaries(st.text(min_size=1, max_size=8), GARBAGE, min_size=1, max_size=1)
    return _weighted((6, complete), (2, partial), (2, st.tuples(complete, unknown).map(lambda kv: {**kv[1], **kv[0]})))


def _all_numbers_finite(obj: typing.Any, where: str = "") -> None:
    if dataclasses.is_dataclass(obj):
        for f in dataclasses.fields(obj):
            _all_numbers_finite(getattr(obj, f.name), f"{where}.{f.name}")
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            _all_numbers_finite(v, f"{where}[{i}]")
    elif isinstance(obj, dict):
        for k, v in obj.items():
            _all_numbers_finite(v, f"{where}.{k}")
    elif isinstance(obj, float):
        assert math.isfinite(obj), (where, obj)


CONFIGS = [
    SafetyConfig,
    DeployConfig,
    BusConfig,
    TimingConfig,
    JointDriveConfig,
    DriveConfig,
    VacuumNodeConfig,
    MasterConfig,
    LimitOverrides,
    CobotBusConfig,
    DetectorConfig,
    BoardConfig,
    MarkerPlacement,
    TargetsConfig,
    RegistrationConfig,
    HmdNoiseConfig,
    CalibrationConfig,
    TwinCalibrationConfig,
    Intrinsics,
    CameraConfig,
    RobotConfig,
    ArmConfig,
    UrdfSource,
    Workspace,
]
ROBOT = load_robot()


@pytest.mark.parametrize("cls", CONFIGS, ids=[c.__name__ for c in CONFIGS])
def test_from_dict_returns_a_finite_config_or_raises_config_error(cls):
    @FUZZ
    @given(_table(cls))
    def check(data):
        try:
            config = from_dict(cls, data, where="fuzz.toml")
        except ConfigError as exc:  # (`mrguide.cli.main` prints any line break in it escaped: one line)
            assert str(exc).startswith("fuzz.toml: ")
            return
        _all_numbers_finite(config)
        if cls is CobotBusConfig:  # what `load_cobot_bus_config(path, robot)` adds
            with contextlib.suppress(ConfigError):
                resolve_limits(config, ROBOT)
        if cls is RobotConfig:  # the arm file with these overrides: a spec, or one RobotSpecError (a ConfigError)
            with contextlib.suppress(ConfigError):
                spec = load_robot(config)
                assert spec.within_limits(spec.q_home) and np.all(np.isfinite(spec.workspace.lo))

    check()


# ---------------------------------------------------------------------------------------------------- CLI
PARSER = build_parser()
NUMERIC_TEXT = st.one_of(
    st.integers().map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.sampled_from(
        [
            "nan",
            "-nan",
            "inf",
            "-inf",
            "Infinity",
            "1e999",
            "-0",
            "0",
            "1",
            "-1",
            "0x10",
            "1_000",
            " 3",
            "3 ",
            "",
            "1.0",
            "2.5",
            "1e3",
            "١",
            "True",
        ]
    ),
    st.text(alphabet="0123456789.-+eEinfa_ x", max_size=8),
)


def _positive_int(v):
    return type(v) is int and v >= 1


def _nonnegative_int(v):
    return type(v) is int and v >= 0


def _positive_float(v):
    return type(v) is float and math.isfinite(v) and v > 0


# (argv before the option, option, attribute, constraint)
OPTIONS = [
    (["expert"], "--episodes", "episodes", _positive_int),
    (["expert"], "--seed", "seed", _nonnegative_int),
    (["deploy", "--policy", "p.npz"], "--episodes", "episodes", _positive_int),
    (["deploy", "--policy", "p.npz"], "--seed", "seed", _nonnegative_int),
    (["main"], "--train-steps", "train_steps", _positive_int),
    (["main"], "--deploy-episodes", "deploy_episodes", _positive_int),
    (["main"], "--seeds", "seeds", _positive_int),
    (["main"], "--episodes", "episodes", _positive_int),
    (["main"], "--seed", "seed", _nonnegative_int),
    (["sim2real", "--policy", "p.npz"], "--seeds", "seeds", _positive_int),
    (["sim2real", "--policy", "p.npz"], "--episodes", "episodes", _positive_int),
    (["bus", "monitor"], "--duration", "duration", _positive_float),
]


def _parse(argv: list[str]) -> argparse.Namespace | None:
    """The parsed namespace, or None if argparse refused (exit 2)."""
    with contextlib.redirect_stderr(io.StringIO()):
        try:
            return PARSER.parse_args(argv)
        except SystemExit as exc:
            assert exc.code == 2
            return None


@pytest.mark.parametrize("before, option, attr, ok", OPTIONS, ids=[f"{o[0][0]} {o[1]}" for o in OPTIONS])
def test_numeric_options_are_refused_or_meet_their_constraint(before, option, attr, ok):
    @settings(max_examples=60, deadline=None)
    @given(NUMERIC_TEXT)
    def check(text):
        args = _parse([*before, f"{option}={text}"])
        if args is not None:
            assert ok(getattr(args, attr)), (option, text, getattr(args, attr))

    check()


@settings(max_examples=120, deadline=None)
@given(
    st.sampled_from(["actuator_latency", "actuator_lag", "object_mass", "tracking_noise_m", "gravity", ""]),
    st.lists(NUMERIC_TEXT, min_size=0, max_size=3),
)
def test_sweep_values_are_refused_or_finite_numbers(name, values):
    args = _parse(["sim2real", "--policy", "p.npz", f"--sweep={name}={','.join(values)}"])
    if args is not None:
        ((parsed_name, parsed),) = args.sweep
        assert parsed_name == name and len(parsed) == len(values) >= 1
        assert all(math.isfinite(v) for v in parsed)
        assert all(type(v) is (int if name == "actuator_latency" else float) for v in parsed)


@settings(max_examples=80, deadline=None)
@given(st.lists(st.sampled_from(["sim", "real_exact", "real_hmd", "real", "", " ", "SIM"]), max_size=4).map(",".join))
def test_conditions_are_refused_or_distinct_known_names(text):
    args = _parse(["sim2real", "--policy", "p.npz", f"--conditions={text}"])
    if args is not None:
        assert args.conditions and len(set(args.conditions)) == len(args.conditions)
        assert set(args.conditions) <= {"sim", "real_exact", "real_hmd"}
