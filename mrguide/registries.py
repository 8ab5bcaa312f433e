"""The one way names are registered where things are added (learners, expert sources, plant engines): a table from
name to entry, and the list of names the configs accept, which must not import what the entries need."""

from __future__ import annotations

from typing import TypeVar

T = TypeVar("T")


def register(table: dict[str, T], names: list[str], name: str, entry: T, kind: str) -> None:
    """Add `entry` as `name` to `table`, and `name` to the configs' `names`; ValueError if the name is taken."""
    if name in table:
        raise ValueError(f"{kind} {name!r} is registered already")
    table[name] = entry
    if name not in names:
        names.append(name)
