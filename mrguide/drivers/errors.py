"""Errors of the driver layer: each names the node (and joint) it concerns.

Faults detected in background threads (receive thread, control cycle) are latched by the `Cobot`
facade and raised from its next call, so the deploy runtime sees them as ordinary exceptions.
"""

from __future__ import annotations


class DriverError(RuntimeError):
    """Base class of everything the CAN driver layer raises at run time."""


class BusError(DriverError):
    """The CAN bus cannot be opened, written or read (interface missing, send failure, dead receiver)."""


class BusOffError(BusError):
    """The CAN controller reported bus-off: it no longer takes part in bus traffic."""


class BootError(DriverError):
    """A node did not boot or could not be configured (NMT boot-up, SDO download, wrong device)."""


class NodeLostError(DriverError):
    """A node stopped communicating or left NMT OPERATIONAL."""

    def __init__(self, message: str, node_id: int, name: str) -> None:
        super().__init__(message)
        self.node_id = node_id
        self.name = name


class HeartbeatLostError(NodeLostError):
    """No heartbeat from a node within its consumer time."""


class FeedbackLostError(NodeLostError):
    """A node's synchronous TPDO feedback missed several consecutive SYNC cycles."""


class DeviceFaultError(DriverError):
    """A node reported an active error: EMCY with a non-zero error register, or a drive in FAULT."""

    def __init__(self, message: str, node_id: int, name: str, emcy_code: int | None) -> None:
        super().__init__(message)
        self.node_id = node_id
        self.name = name
        self.emcy_code = emcy_code


class SetpointError(DriverError, ValueError):
    """A joint setpoint or vacuum command was refused before anything was sent."""


class NotReadyError(DriverError):
    """The call needs a state the cobot is not in (not connected, not enabled)."""
