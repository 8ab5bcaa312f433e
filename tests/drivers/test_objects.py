"""The CANopen objects are named once (`mrguide/drivers/objects.py`): every name is an object of the shipped EDS
files, and no driver module (master or simulated device) writes an object's index as a number of its own."""

from __future__ import annotations

import io
import tokenize
from pathlib import Path

import canopen
import pytest

from mrguide.drivers import objects

DRIVERS = Path(objects.__file__).parent
EDS = {name: canopen.import_od(str(DRIVERS / "eds" / f"{name}.eds")) for name in ("cia402_drive", "vacuum_generator")}
VACUUM_NAMES = {"VACUUM_COMMAND", "PART_GRIPPED", "PART_LOST", "VACUUM_LEVEL", "GRIP_THRESHOLD", "GRIP_HYSTERESIS"}
#: Indexes that are also plain bit masks in the drivers (statusword bits 12 and 13, the communication area's bounds).
AMBIGUOUS = {0x1000, 0x2000}


def _named() -> dict[str, int]:
    return {k: v for k, v in vars(objects).items() if k.isupper() and isinstance(v, int)}


@pytest.mark.parametrize("name", sorted(_named()))
def test_every_named_object_is_in_the_eds_of_the_device_that_holds_it(name):
    index = _named()[name]
    if name.startswith(("RPDO", "TPDO")) or index < 0x2000:  # CiA 301: both devices
        holders = ["cia402_drive", "vacuum_generator"]
    else:
        holders = ["vacuum_generator"] if name in VACUUM_NAMES else ["cia402_drive"]
    for device in holders:
        assert index in EDS[device], f"{name} = {index:#06x} is not in {device}.eds"


def test_no_driver_module_spells_a_named_index_itself():
    named = set(_named().values()) - AMBIGUOUS
    found = []
    for path in sorted(DRIVERS.rglob("*.py")):
        if path.name == "objects.py":
            continue
        for tok in tokenize.generate_tokens(io.StringIO(path.read_text()).readline):
            if tok.type == tokenize.NUMBER and tok.string.lower().startswith("0x") and int(tok.string, 16) in named:
                found.append(f"{path.relative_to(DRIVERS)}:{tok.start[0]}: {tok.string}")
    assert not found, "use the names of mrguide/drivers/objects.py:\n" + "\n".join(found)
