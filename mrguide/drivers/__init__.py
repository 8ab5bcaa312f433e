"""CAN driver layer: the cobot's CiA 402 joint drives and vacuum generator over CANopen.

The deploy runtime relies on `CobotInterface` (enable, stream setpoints, read state, vacuum, stop), which
`Cobot` implements over CANopen (plus connect and disconnect);
`drivers.mock` provides simulated devices on python-can's `virtual` interface for hardware-free runs.
"""

from mrguide.drivers.cobot import Cobot
from mrguide.drivers.cobot_state import CobotStatus, CycleSample, DriverStats, JointState, VacuumState
from mrguide.drivers.config import CobotBusConfig, load_cobot_bus_config
from mrguide.drivers.errors import (
    BootError,
    BusError,
    BusOffError,
    DeviceFaultError,
    DriverError,
    FeedbackLostError,
    HeartbeatLostError,
    NodeLostError,
    NotReadyError,
    SetpointError,
)
from mrguide.drivers.interface import CobotInterface

__all__ = [
    "BootError",
    "BusError",
    "BusOffError",
    "Cobot",
    "CobotBusConfig",
    "CobotInterface",
    "CobotStatus",
    "CycleSample",
    "DeviceFaultError",
    "DriverError",
    "DriverStats",
    "FeedbackLostError",
    "HeartbeatLostError",
    "JointState",
    "NodeLostError",
    "NotReadyError",
    "SetpointError",
    "VacuumState",
    "load_cobot_bus_config",
]
