"""CAN driver layer: the cobot's CiA 402 joint drives and vacuum generator over CANopen.

The deploy runtime relies on `CobotInterface` (enable, stream setpoints, read state, vacuum, stop), which
`Cobot` implements over CANopen (plus connect and disconnect);
`drivers.mock` provides simulated devices on python-can's `virtual` interface for hardware-free runs.

The names below load on first use, so that importing `mrguide.drivers.errors` (the `mrguide` command does,
to catch DriverError) needs neither python-can nor canopen: the CLI starts on an install without them.
"""

import importlib

_ERRORS = (
    "BootError",
    "BusError",
    "BusOffError",
    "DeviceFaultError",
    "DriverError",
    "FeedbackLostError",
    "HeartbeatLostError",
    "NodeLostError",
    "NotReadyError",
    "SetpointError",
)
_STATE = ("CobotStatus", "CycleSample", "DriverStats", "JointState", "VacuumState")
#: name -> the module that defines it
_HOME = {
    "Cobot": "mrguide.drivers.cobot",
    "CobotBusConfig": "mrguide.drivers.config",
    "load_cobot_bus_config": "mrguide.drivers.config",
    "CobotInterface": "mrguide.drivers.interface",
    **dict.fromkeys(_STATE, "mrguide.drivers.cobot_state"),
    **dict.fromkeys(_ERRORS, "mrguide.drivers.errors"),
}

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


def __getattr__(name: str):
    home = _HOME.get(name)
    if home is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = globals()[name] = getattr(importlib.import_module(home), name)
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *_HOME})
