"""EDS files checked when the bus description is loaded: readable, and holding the objects the driver uses.

So a wrong or corrupt file is refused with one message naming it, before any node or simulated device is
created from it (canopen would raise deep inside a third-party parser, or later on a missing object).
"""

from __future__ import annotations

import functools
from pathlib import Path

import canopen

from mrguide.config import ConfigError
from mrguide.drivers.objects import (
    CONSUMER_HEARTBEAT_TIME,
    CONTROLWORD,
    DEVICE_TYPE,
    FOLLOWING_ERROR_TIME_OUT,
    FOLLOWING_ERROR_WINDOW,
    GRIP_HYSTERESIS,
    GRIP_THRESHOLD,
    INTERPOLATION_TIME_PERIOD,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    PART_GRIPPED,
    PART_LOST,
    POSITION_ACTUAL_VALUE,
    PRODUCER_HEARTBEAT_TIME,
    QUICK_STOP_DECELERATION,
    QUICK_STOP_OPTION_CODE,
    RPDO_COMMUNICATION,
    RPDO_MAPPING,
    STATUSWORD,
    SUPPORTED_DRIVE_MODES,
    TARGET_POSITION,
    TPDO_COMMUNICATION,
    TPDO_MAPPING,
    VACUUM_COMMAND,
    VACUUM_LEVEL,
    VELOCITY_ACTUAL_VALUE,
)

#: Objects the master reads or writes on every device: device type, heartbeat consumer/producer time,
#: RPDO1 and TPDO1 communication and mapping parameters.
_COMMON = (
    DEVICE_TYPE,
    CONSUMER_HEARTBEAT_TIME,
    PRODUCER_HEARTBEAT_TIME,
    RPDO_COMMUNICATION,
    RPDO_MAPPING,
    TPDO_COMMUNICATION,
    TPDO_MAPPING,
)
#: Objects of a CiA 402 joint drive used by `cia402.py` (TPDO2 for the velocity, when mapped, is added).
DRIVE_OBJECTS = _COMMON + (
    CONTROLWORD,
    STATUSWORD,
    QUICK_STOP_OPTION_CODE,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    POSITION_ACTUAL_VALUE,
    FOLLOWING_ERROR_WINDOW,
    FOLLOWING_ERROR_TIME_OUT,
    TARGET_POSITION,
    QUICK_STOP_DECELERATION,
    INTERPOLATION_TIME_PERIOD,
    SUPPORTED_DRIVE_MODES,
)
VELOCITY_TPDO_OBJECTS = (TPDO_COMMUNICATION + 1, TPDO_MAPPING + 1, VELOCITY_ACTUAL_VALUE)  # TPDO2
#: Objects of the vacuum generator used by `vacuum.py`.
VACUUM_OBJECTS = _COMMON + (VACUUM_COMMAND, PART_GRIPPED, PART_LOST, VACUUM_LEVEL, GRIP_THRESHOLD, GRIP_HYSTERESIS)


def check_eds(path: Path, required: tuple[int, ...], key: str) -> None:
    """ConfigError naming `key` (e.g. "drives.eds") and the file unless `path` is a readable EDS file with
    every object in `required`."""
    if not path.is_file():
        raise ConfigError(f"{key}: EDS file not found: {str(path)!r}")
    stat = path.stat()
    problem = _eds_problem(str(path.resolve()), stat.st_mtime_ns, stat.st_size, required)
    if problem:
        raise ConfigError(f"{key}: {path}: {problem}")


@functools.lru_cache(maxsize=32)
def _eds_problem(path: str, mtime_ns: int, size: int, required: tuple[int, ...]) -> str | None:
    """Why the file is not a usable EDS, or None; cached per file version (configs are built often)."""
    try:
        od = canopen.import_od(path, 1)
    except Exception as exc:  # configparser, ValueError, UnicodeDecodeError... from a third-party file format
        detail = " ".join(str(exc).split())
        return f"not a readable EDS file ({detail[:200]})"
    missing = [f"0x{index:04X}" for index in required if index not in od]
    return f"lacks object(s) {', '.join(missing)} that the driver uses" if missing else None
