"""Typed configuration: dataclasses with defaults, loadable from TOML files in `configs/`."""

from __future__ import annotations

import dataclasses
import math
import tomllib
import types
import typing
from pathlib import Path
from typing import Annotated, Any, TypeVar

import dacite

from mrguide.errors import InputError

T = TypeVar("T")


class ConfigError(InputError):
    """A configuration file or value is invalid; the message names the file and the key."""


def check_number(key: str, value: Any, low: float, high: float, unit: str = "", integer: bool = False) -> None:
    """Refuse `value` of `key` (e.g. "safety.stall_timeout") unless it is a finite number in [low, high].

    For `__post_init__` checks: loaded through `from_dict`, the message also gets the file and section.
    NaN fails every comparison, so it is refused like any other value out of range.
    """
    kinds = (int,) if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kinds) or not (math.isfinite(value) and low <= value <= high):
        kind = "an integer" if integer else "a finite number"
        raise ConfigError(f"{key} = {value!r}: expected {kind} in [{low:g}, {high:g}]{unit}")


_RANGED: dict[type, tuple[tuple[str, Range, bool], ...]] = {}


@dataclasses.dataclass(frozen=True)
class Range:
    """A number field's range, declared with the field: `tau: Annotated[float, Range(1e-6, 1.0)] = 0.005`.

    `check_ranges` enforces it (an `int` field must also be a whole number); `unit` ends the error message."""

    low: float
    high: float
    unit: str = ""


def _ranged_fields(cls: type) -> tuple[tuple[str, Range, bool], ...]:
    """(name, range, integer) of every field of dataclass `cls` declared `Annotated[int | float, Range(...)]`
    (read once per class)."""
    if cls in _RANGED:
        return _RANGED[cls]
    hints = typing.get_type_hints(cls, include_extras=True)
    ranged = []
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        if typing.get_origin(hint) is Annotated:
            base, *extras = typing.get_args(hint)
            ranged += [(f.name, r, base is int) for r in extras if isinstance(r, Range)]
    _RANGED[cls] = tuple(ranged)
    return _RANGED[cls]


def check_ranges(obj: object, section: str) -> None:
    """Refuse the first field of dataclass instance `obj` outside its declared `Range`, naming it `section.field`.

    For `__post_init__`, so that a config built in code is checked as one read from a file. A field declared
    `X | None` may be None (an override left unset)."""
    for name, r, integer in _ranged_fields(type(obj)):
        value = getattr(obj, name)
        if value is not None:
            check_number(f"{section}.{name}", value, r.low, r.high, r.unit, integer)


def from_dict(cls: type[T], data: dict[str, Any], where: str = "config") -> T:
    """Build dataclass `cls` from `data`; unknown keys, wrong types, NaN/inf and values out of range raise
    ConfigError naming `where` and the key."""
    problem = _number_problem(cls, data, "")
    if problem:
        raise ConfigError(f"{where}: {problem}")
    refusal = _choice_refusal(cls, data)
    if refusal:
        raise ConfigError(f"{where}: {refusal}")
    try:
        return dacite.from_dict(
            cls, data, config=dacite.Config(strict=True, cast=[tuple], type_hooks={float: _to_float})
        )
    except (dacite.DaciteError, TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: {exc}") from exc


def _number_problem(cls: Any, data: Any, prefix: str) -> str | None:
    """The first number in `data` that cannot be a value of type `cls`: wrong type or not finite.

    Walks dataclasses, tuples (of numbers, of points, of tables) and plain numbers. Every float of every
    config must be finite (no setting means "off" by NaN or inf); range checks are in each dataclass's
    `__post_init__` (`check_ranges` of the fields' declared `Range`, `check_number` for the rest). Other mismatches are left to dacite, which names them too.
    """
    key = prefix.rstrip(".")
    if cls in (float, int):
        return _scalar_problem(key, data, cls)
    if dataclasses.is_dataclass(cls):
        if not isinstance(data, dict):
            return None
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            if f.name in data:
                problem = _number_problem(hints[f.name], data[f.name], f"{prefix}{f.name}.")
                if problem:
                    return problem
        return None
    args = typing.get_args(cls)
    if typing.get_origin(cls) in (typing.Union, types.UnionType):  # `X | None`: an override left unset
        present = [a for a in args if a is not type(None)]
        return _number_problem(present[0], data, prefix) if len(present) == 1 and data is not None else None
    if typing.get_origin(cls) is tuple and args and isinstance(data, (list, tuple)):
        items = [args[0]] * len(data) if len(args) == 2 and args[1] is Ellipsis else list(args)
        for i, (item_type, value) in enumerate(zip(items, data)):
            problem = _number_problem(item_type, value, f"{key}[{i}].")
            if problem:
                return problem
    return None


def _choice_refusal(cls: Any, data: Any) -> ConfigError | None:
    """The dataclass's own refusal of a value outside a `Literal` field's choices (or a tuple of them), or None.

    dacite would refuse it first, naming only the type; so the value is set alone on a default instance, whose
    `__post_init__` says what the key takes. None also when there is no such value, or nothing refuses it there
    (dacite then names it)."""
    if not (isinstance(cls, type) and dataclasses.is_dataclass(cls)) or not isinstance(data, dict):
        return None
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        if f.name not in data:
            continue
        hint, value = hints[f.name], data[f.name]
        if dataclasses.is_dataclass(hint):
            refusal = _choice_refusal(hint, value)
            if refusal:
                return refusal
        elif _outside_choices(hint, value):
            try:
                as_loaded = tuple(value) if typing.get_origin(hint) is tuple and isinstance(value, list) else value
                dataclasses.replace(cls(), **{f.name: as_loaded})
            except ConfigError as exc:
                return exc
            except Exception:  # no default instance to try it on: left to dacite
                return None
    return None


def _outside_choices(hint: Any, value: Any) -> bool:
    """`value` is not among the choices of `Literal` type `hint`, or not all of a `tuple[Literal[...], ...]`."""
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is typing.Literal:
        return not any(value == a and type(value) is type(a) for a in args)
    if origin is tuple and len(args) == 2 and args[1] is Ellipsis and typing.get_origin(args[0]) is typing.Literal:
        return not isinstance(value, (list, tuple)) or any(_outside_choices(args[0], v) for v in value)
    return False


def _scalar_problem(key: str, value: Any, kind: type) -> str | None:
    if kind is int and (isinstance(value, bool) or not isinstance(value, int)):
        return f"{key} = {value!r}: expected an integer"
    if kind is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return f"{key} = {value!r}: expected a number"
        if not math.isfinite(value):
            return f"{key} = {value!r}: must be finite"
    return None


def _to_float(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise TypeError(f"expected a number, got {value!r}")
    return float(value)


def load_toml(path: str | Path) -> dict[str, Any]:
    """Read a TOML file; a missing or malformed file raises ConfigError naming it."""
    path = Path(path)
    try:
        with path.open("rb") as fh:
            return tomllib.load(fh)
    except FileNotFoundError as exc:
        raise ConfigError(f"config file not found: {path}") from exc
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from exc


#: The sections a run config may hold besides its learners' (a learner's section is named by its registry entry,
#: `policies.learners`, and known to `mrguide train` and `mrguide config show`, which import the registry): one file
#: may serve several commands (`configs/cells/real_cell.toml` is read by `deploy` and `sim2real`), so each command
#: reads its sections and any other known one is left to the command it belongs to; an unknown section (a typo:
#: `[deplyo]`) is refused instead of ignored. The shipped learners' sections are listed for the commands that do
#: not import the learner registry (deploy, the cell, calibration).
RUN_SECTIONS = (
    "robot",
    "task",
    "twin",
    "train",
    "ddpg",
    "sac",
    "guidance",
    "deploy",
    "safety",
    "calibration",
    "calibration_twin",
    "plant",
)


@dataclasses.dataclass(frozen=True)
class ConfigFile:
    """A run config file parsed once: its sections' tables, each read into its dataclass by name (`section`).

    `path` None is the empty file: every section at its defaults."""

    path: Path | None = None
    tables: dict[str, Any] = dataclasses.field(default_factory=dict)

    @classmethod
    def read(cls, path: str | Path | None, known: tuple[str, ...] = RUN_SECTIONS) -> ConfigFile:
        """Parse `path` (ConfigError naming it if it is missing or malformed); only the sections in `known`."""
        if path is None:
            return cls()
        whole = load_toml(path)
        unknown = [key for key in whole if key not in known]
        if unknown:
            raise ConfigError(
                f"{path}: unknown section [{unknown[0]}]; this file may hold " + ", ".join(f"[{k}]" for k in known)
            )
        return cls(Path(path), whole)

    def optional(self, cls: type[T], section: str) -> T | None:
        """`[section]` read into dataclass `cls`; None when the section is absent (the caller picks defaults)."""
        return self.section(cls, section) if section in self.tables else None

    def section(self, cls: type[T], section: str) -> T:
        """`[section]` read into dataclass `cls`; its defaults when the section is absent."""
        data = self.tables.get(section, {})
        if not isinstance(data, dict):
            raise ConfigError(f"{self.path}: [{section}] must be a table")
        return from_dict(cls, data, where=f"{self.path} [{section}]") if self.path else cls()


def load_section(cls: type[T], path: str | Path | None, section: str, known: tuple[str, ...] = RUN_SECTIONS) -> T:
    """Load `[section]` of TOML file `path` into `cls`; defaults when `path` is None or the section is absent.

    The file may hold only the sections in `known`; any other top-level key raises ConfigError naming it. For a
    command that reads one section; one that reads several parses the file once (`ConfigFile`)."""
    return ConfigFile.read(path, known).section(cls, section)


def load_optional_section(cls: type[T], path: str | Path | None, section: str) -> T | None:
    """Like `load_section`, but None when the file or the section is absent (the caller picks defaults)."""
    return ConfigFile.read(path).optional(cls, section)


def replace_path(obj: T, path: str, value: Any, where: str = "override") -> T:
    """A copy of config `obj` with the field at dotted `path` (e.g. "noise.sigma") set to `value`.

    Checked exactly as a value read from a file (types, finiteness, unknown keys, ranges).
    """
    data = to_dict(obj)
    node, keys, cls = data, path.split("."), type(obj)
    for key in keys[:-1]:
        table = _table_type(cls, key)
        if node.get(key) is None and table is not None:  # an optional table left unset: from its defaults
            node[key] = to_dict(table())
        cls = table
        if not isinstance(node.get(key), dict):
            raise ConfigError(f"{where}: {path}: {key!r} is not a table of {type(obj).__name__}")
        node = node[key]
    if keys[-1] not in node:
        raise ConfigError(f"{where}: {path}: no such key in {type(obj).__name__}")
    node[keys[-1]] = value
    return from_dict(type(obj), data, where)


def _table_type(cls: Any, key: str) -> Any:
    """The dataclass that field `key` of dataclass `cls` holds (`X | None` unwrapped), or None if it holds none."""
    if not dataclasses.is_dataclass(cls):
        return None
    hint = typing.get_type_hints(cls).get(key)
    present = [a for a in typing.get_args(hint) if a is not type(None)] or [hint]
    return present[0] if len(present) == 1 and dataclasses.is_dataclass(present[0]) else None


def to_dict(obj: Any) -> dict[str, Any]:
    """A dataclass as a plain dict (tuples become lists), for metadata and logs."""
    return dataclasses.asdict(obj)
