"""Typed access to what canopen hands back untyped: a node's ID and the values of integer objects.

canopen types every decoded object value (`raw`, `decode_raw`) as any value an object can hold (int, bool,
float, str, bytes) and a node's ID as optional. The objects the driver reads are integers (UNSIGNEDxx,
INTEGERxx: canopen decodes them to `int`) and every node is created with its ID; these helpers say so to
the type checker, and fail loudly if a device's dictionary ever says otherwise.
"""

from __future__ import annotations

from canopen.node.base import BaseNode


def od_int(value: object) -> int:
    """The value of an integer object as canopen decoded it (TypeError for a non-integer object)."""
    if not isinstance(value, int):
        raise TypeError(f"expected the value of an integer object, got {value!r}")
    return value


def node_id_of(node: BaseNode) -> int:
    """The ID of a node created with one (canopen types it as optional: taken from the EDS if not given)."""
    if node.id is None:
        raise ValueError("CANopen node without a node ID")
    return node.id
