"""Which settings a config dataclass has and which a shipped TOML file documents (for the reference tests)."""

from __future__ import annotations

import dataclasses
import re
import typing


def setting_names(cls: type, prefix: str = "") -> set[str]:
    """Dotted names of every setting of config dataclass `cls`: nested tables and arrays of tables included."""
    out: set[str] = set()
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        kind = hints[f.name]
        args = typing.get_args(kind)
        if typing.get_origin(kind) is tuple and args and dataclasses.is_dataclass(args[0]):
            kind = args[0]  # tuple[Table, ...]: an array of tables, [[name]]
        out |= setting_names(kind, f"{prefix}{f.name}.") if dataclasses.is_dataclass(kind) else {prefix + f.name}
    return out


def documented_keys(text: str) -> set[str]:
    """Dotted names a TOML file sets, or shows as a commented-out example (`# key = ...`) in its table."""
    keys, table = set(), ""
    for line in text.splitlines():
        line = line.strip()
        if m := re.match(r"^\[\[?([\w.]+)\]\]?", line):
            table = m.group(1) + "."
        elif m := re.match(r"^#?\s*(\w+)\s*=", line):
            keys.add(table + m.group(1))
    return keys


def undocumented(cls: type, prefix: str, text: str) -> set[str]:
    """Settings of `cls` that TOML `text` neither sets nor shows; an inline array of tables (`markers = [{...}]`)
    documents its members."""
    documented = documented_keys(text)

    def shown(name: str) -> bool:
        parts = name.split(".")
        return any(".".join(parts[:n]) in documented for n in range(1, len(parts) + 1))

    return {name for name in setting_names(cls, prefix) if not shown(name)}
