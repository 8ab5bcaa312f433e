"""PDO mapping by SDO through canopen's PDO API, shared by the drive and vacuum-generator masters."""

from __future__ import annotations

from collections.abc import Mapping

from canopen.pdo import PdoBase, PdoVariable

from mrguide.drivers.errors import BootError

#: A PDO layout: (index, subindex) of each mapped object, in frame order.
PdoEntries = tuple[tuple[int, int], ...]

#: Transmission type "synchronous, every SYNC" (CiA 301).
SYNC_EVERY_CYCLE = 1


def map_pdos(pdos: PdoBase, layouts: Mapping[int, PdoEntries], where: str) -> dict[int, list[PdoVariable]]:
    """Write `layouts[n]` into PDO n of one direction (RPDO or TPDO) and disable every other PDO.

    Mapped PDOs are synchronous on every SYNC. Returns the mapped canopen variables per PDO number.
    """
    mapped: dict[int, list[PdoVariable]] = {}
    assert pdos.map is not None, "a node's RPDO or TPDO collection"  # None only on canopen's bare PdoBase
    for number, pdo_map in pdos.map.items():
        entries = layouts.get(number, ())
        pdo_map.clear()
        pdo_map.cob_id = pdo_map.predefined_cob_id
        variables = []
        for index, subindex in entries:
            var = pdo_map.add_variable(index, subindex)
            if var is None:
                raise BootError(f"{where}: object 0x{index:04X}:{subindex:02X} is missing from the EDS")
            variables.append(var)
        pdo_map.enabled = bool(entries)
        pdo_map.trans_type = SYNC_EVERY_CYCLE if entries else None
        if entries:
            mapped[number] = variables
    pdos.save()
    return mapped
