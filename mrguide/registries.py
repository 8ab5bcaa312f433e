"""The one way names are registered where things are added (learners, expert sources, plant engines): a table from
name to entry, and, where a config that must not import the entries checks a name, the list of names it accepts."""

from __future__ import annotations

from typing import TypeVar

T = TypeVar("T")


def register(table: dict[str, T], name: str, entry: T, kind: str, names: list[str] | None = None) -> None:
    """Add `entry` as `name` to `table` (and `name` to the configs' `names`, if given); ValueError if it is taken."""
    if name in table:
        raise ValueError(f"{kind} {name!r} is registered already")
    table[name] = entry
    if names is not None and name not in names:
        names.append(name)
