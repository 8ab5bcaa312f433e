"""EDS files checked when the bus description is loaded: readable, and holding the objects the driver uses.

So a wrong or corrupt file is refused with one message naming it, before any node or simulated device is
created from it (canopen would raise deep inside a third-party parser, or later on a missing object).
"""

from __future__ import annotations

import functools
from pathlib import Path

import canopen

from mrguide.config import ConfigError

#: Objects the master reads or writes on every device: device type, heartbeat consumer/producer time,
#: RPDO1 and TPDO1 communication and mapping parameters.
_COMMON = (0x1000, 0x1016, 0x1017, 0x1400, 0x1600, 0x1800, 0x1A00)
#: Objects of a CiA 402 joint drive used by `cia402.py` (TPDO2 for the velocity, when mapped, is added).
DRIVE_OBJECTS = _COMMON + (
    0x6040,
    0x6041,
    0x605A,
    0x6060,
    0x6061,
    0x6064,
    0x6065,
    0x6066,
    0x607A,
    0x6085,
    0x60C2,
    0x6502,
)
VELOCITY_TPDO_OBJECTS = (0x1801, 0x1A01, 0x606C)
#: Objects of the vacuum generator used by `vacuum.py`.
VACUUM_OBJECTS = _COMMON + (0x2000, 0x2001, 0x2003, 0x2020, 0x2100, 0x2101)


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
