"""Slave-side PDO layouts read from a LocalNode's own object dictionary (what the master wrote by SDO)."""

from __future__ import annotations

import logging
import struct
from collections.abc import Callable
from dataclasses import dataclass

from canopen import LocalNode
from canopen.objectdictionary import (
    BOOLEAN,
    INTEGER8,
    INTEGER16,
    INTEGER32,
    UNSIGNED8,
    UNSIGNED16,
    UNSIGNED32,
    ODArray,
    ODRecord,
)
from canopen.pdo.base import PDO_NOT_VALID
from canopen.sdo import SdoArray, SdoRecord

from mrguide.drivers.od_values import od_int

logger = logging.getLogger(__name__)

#: Transmission types 1..240: synchronous, every n-th SYNC (CiA 301).
SYNC_TYPES = range(1, 241)

_FORMATS = {
    BOOLEAN: "?",
    INTEGER8: "b",
    UNSIGNED8: "B",
    INTEGER16: "h",
    UNSIGNED16: "H",
    INTEGER32: "i",
    UNSIGNED32: "I",
}

Key = tuple[int, int]


@dataclass(frozen=True)
class PdoLayout:
    """One enabled PDO: COB-ID, transmission type and the objects packed into its frame."""

    number: int
    cob_id: int
    trans_type: int
    entries: tuple[Key, ...]
    codec: struct.Struct

    @property
    def size(self) -> int:
        return self.codec.size

    def unpack(self, data: bytes) -> dict[Key, int]:
        return dict(zip(self.entries, self.codec.unpack(data)))

    def pack(self, value: Callable[[Key], int]) -> bytes:
        return self.codec.pack(*(value(key) for key in self.entries))


def read_layouts(node: LocalNode, comm_base: int, map_base: int) -> list[PdoLayout]:
    """Enabled PDOs of one direction as currently configured in `node`'s dictionary.

    A PDO whose mapping does not match the dictionary (unknown object, wrong bit length) is left out
    and logged: the device would not process it.
    """
    od = node.object_dictionary
    layouts = []
    n = 0
    while comm_base + n in od:
        comm, mapping = node.sdo[comm_base + n], node.sdo[map_base + n]
        assert isinstance(comm, (SdoRecord, SdoArray)) and isinstance(mapping, (SdoRecord, SdoArray))
        cob_id = od_int(comm[1].raw)
        if not cob_id & PDO_NOT_VALID:
            entries, fmt = [], "<"
            for sub in range(1, od_int(mapping[0].raw) + 1):
                raw = od_int(mapping[sub].raw)
                index, subindex, bits = raw >> 16, (raw >> 8) & 0xFF, raw & 0xFF
                obj = od.get(index)
                if isinstance(obj, (ODRecord, ODArray)):
                    obj = obj.get(subindex)
                if obj is None or obj.data_type not in _FORMATS or len(obj) != bits:
                    logger.error(
                        "node %d: PDO 0x%04X maps 0x%08X, which is invalid; PDO not processed",
                        node.id,
                        comm_base + n,
                        raw,
                    )
                    break
                entries.append((index, subindex))
                fmt += _FORMATS[obj.data_type]
            else:
                layouts.append(
                    PdoLayout(n + 1, cob_id & 0x7FF, od_int(comm[2].raw), tuple(entries), struct.Struct(fmt))
                )
        n += 1
    return layouts
