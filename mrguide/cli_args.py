"""argparse value types that refuse bad numbers at parse time, with the option named in the message."""

from __future__ import annotations

import argparse
import math
import tomllib
from typing import Any


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser, but an option given "--" as its value is an error.

    Python 3.11's argparse drops that "--" and hands the option an empty list (`--episodes --` gives
    episodes = []), which would fail later with a traceback. Subparsers inherit this class.
    """

    def _get_values(self, action: argparse.Action, arg_strings: list[str]):
        if action.option_strings and action.nargs is None and arg_strings == ["--"]:
            self.error(f"argument {'/'.join(action.option_strings)}: expected a value, got '--'")
        return super()._get_values(action, arg_strings)


def positive_int(text: str) -> int:
    """An integer >= 1."""
    value = _int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 1, got {text!r}")
    return value


def nonnegative_int(text: str) -> int:
    """An integer >= 0."""
    value = _int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a whole number >= 0, got {text!r}")
    return value


def positive_float(text: str) -> float:
    """A finite number > 0."""
    value = finite_float(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"must be > 0, got {text!r}")
    return value


def nonnegative_float(text: str) -> float:
    """A finite number >= 0."""
    value = finite_float(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {text!r}")
    return value


def finite_float(text: str) -> float:
    """A finite number (no nan, inf)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    return value


def _int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a whole number: {text!r}") from None


def override_arg(text: str) -> tuple[str, Any]:
    """argparse type of --set: KEY=VALUE, the value a TOML value (`0.001`, `true`, `[64, 64]`, `"live"`) or else
    the text as it is (`guidance.source=oracle`). Whether the key exists and the value fits is the config's check."""
    key, sep, raw = text.partition("=")
    if not sep or not key.strip() or "." not in key:
        raise argparse.ArgumentTypeError(f"expected SECTION.KEY=VALUE (e.g. ddpg.lr_actor=0.001), got {text!r}")
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError:
        value = raw
    return key.strip(), value


def add_set_argument(parser: argparse.ArgumentParser, help_text: str) -> None:
    """The repeatable `--set SECTION.KEY=VALUE` of every command that takes a config (`override_arg` values in
    `args.set`, a list of (key, value))."""
    parser.add_argument(
        "--set", type=override_arg, action="append", default=[], metavar="SECTION.KEY=VALUE", help=help_text
    )
