"""Live decoding of the cobot's CAN traffic into readable lines: NMT, SYNC, PDOs, SDO, EMCY, heartbeats.

The decoder knows the cobot's nodes, their EDS files and the PDO layouts the master configures, so PDO
fields are shown by name and, for the drives, also in rad / rad/s.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Sequence

import can
import canopen
from canopen.emcy import EMCY_STRUCT, EmcyError
from canopen.nmt import NMT_COMMANDS
from canopen.objectdictionary import ODArray, ODRecord, ODVariable

from mrguide.drivers import vacuum as vac
from mrguide.drivers.bus import open_bus
from mrguide.drivers.cia402 import RPDO_LAYOUT, decode_state, tpdo_layout
from mrguide.drivers.config import CobotBusConfig, eds_path
from mrguide.drivers.conversion import JointConversion
from mrguide.drivers.heartbeat import nmt_state_name
from mrguide.drivers.objects import (
    CONTROLWORD,
    PART_GRIPPED,
    PART_LOST,
    POSITION_ACTUAL_VALUE,
    STATUSWORD,
    TARGET_POSITION,
    VACUUM_COMMAND,
    VACUUM_LEVEL,
    VELOCITY_ACTUAL_VALUE,
)
from mrguide.drivers.pdo_setup import PdoEntries

_NMT_NAMES = {code: name for name, code in NMT_COMMANDS.items() if name != "INITIALISING"}
_SDO_CLIENT = {
    0: "download segment",
    1: "download",
    2: "upload",
    3: "upload segment",
    4: "abort",
    5: "block upload",
    6: "block download",
}
_SDO_SERVER = {
    0: "upload segment",
    1: "download segment",
    2: "upload",
    3: "download",
    4: "abort",
    5: "block download",
    6: "block upload",
}
#: SDO command byte bits: expedited transfer, size indicated.
_EXPEDITED, _SIZE_SPECIFIED = 0x02, 0x01


class _PdoField:
    def __init__(self, var: ODVariable, conversion: JointConversion | None) -> None:
        self.var = var
        self.conversion = conversion
        self.size = len(var) // 8

    def format(self, raw: bytes) -> str:
        value = self.var.decode_raw(raw)
        if isinstance(value, (bytes, bytearray)):  # DOMAIN, OCTET_STRING: shown as b'...' (what str() gives)
            return f"{self.var.name}={value!r}"
        if not isinstance(value, int):  # a string or a real: none of the integer objects below
            return f"{self.var.name}={value}"
        conv, key = self.conversion, (self.var.index, self.var.subindex)
        if key == (CONTROLWORD, 0):
            return f"controlword=0x{value:04X}"
        if key == (STATUSWORD, 0):
            return f"statusword=0x{value:04X} ({decode_state(value)})"
        if key in ((TARGET_POSITION, 0), (POSITION_ACTUAL_VALUE, 0)) and conv is not None:
            name = "target" if key[0] == TARGET_POSITION else "position"
            return f"{name}={value} ({conv.to_rad(value):+.4f} rad)"
        if key == (VELOCITY_ACTUAL_VALUE, 0) and conv is not None:
            return f"velocity={value} ({conv.velocity_to_rad(value):+.3f} rad/s)"
        if key == (VACUUM_COMMAND, 0):
            return f"vacuum={'on' if value & vac.VACUUM_ON_BIT else 'off'} blow_off={'on' if value & vac.BLOW_OFF_BIT else 'off'}"
        if key == (VACUUM_LEVEL, 1):
            return f"level={value * vac.LEVEL_UNIT_KPA:.1f} kPa"
        if key in ((PART_GRIPPED, 0), (PART_LOST, 0)):
            return f"{'gripped' if key[0] == PART_GRIPPED else 'lost'}={'yes' if value & vac.MODULE0_BIT else 'no'}"
        return f"{self.var.name}={value}"


class FrameDecoder:
    """One readable line (and a traffic class) per CAN frame of the cobot's bus."""

    def __init__(self, config: CobotBusConfig, joint_names: Sequence[str]) -> None:
        self._names = {j.node_id: name for j, name in zip(config.joints, joint_names)}
        self._names[config.vacuum.node_id] = "vacuum"
        self._names[config.master.node_id] = "master"
        self._pdos: dict[int, tuple[str, list[_PdoField]]] = {}
        self._ods: dict[int, canopen.ObjectDictionary] = {}
        for joint in config.joints:
            od = self._ods[joint.node_id] = canopen.import_od(str(eds_path(config.drives.eds)), joint.node_id)
            conv = JointConversion.from_config(joint)
            self._add_pdos(od, joint.node_id, RPDO_LAYOUT, tpdo_layout(config.drives.velocity_tpdo), conv)
        od = self._ods[config.vacuum.node_id] = canopen.import_od(
            str(eds_path(config.vacuum.eds)), config.vacuum.node_id
        )
        self._add_pdos(od, config.vacuum.node_id, vac.RPDO_LAYOUT, vac.TPDO_LAYOUT, None)

    def _add_pdos(
        self,
        od: canopen.ObjectDictionary,
        node_id: int,
        rx: dict[int, PdoEntries],
        tx: dict[int, PdoEntries],
        conv: JointConversion | None,
    ) -> None:
        for layouts, base, kind in ((rx, 0x200, "RPDO"), (tx, 0x180, "TPDO")):
            for number, entries in layouts.items():
                fields = []
                for index, subindex in entries:
                    obj = od[index]
                    fields.append(_PdoField(obj[subindex] if isinstance(obj, (ODRecord, ODArray)) else obj, conv))
                self._pdos[base + 0x100 * (number - 1) + node_id] = (f"{kind}{number}", fields)

    def _node(self, node_id: int) -> str:
        name = self._names.get(node_id)
        return f"node {node_id} ({name})" if name else f"node {node_id}"

    def decode(self, msg: can.Message) -> tuple[str, str]:
        """(traffic class, text) for one frame."""
        data = bytes(msg.data)
        cob, node_id = msg.arbitration_id, msg.arbitration_id & 0x7F
        if msg.is_error_frame:
            return "error", f"ERROR FRAME 0x{cob:X} [{data.hex(' ')}]"
        if msg.is_extended_id:
            return "unknown", f"29-bit ID 0x{cob:08X} [{data.hex(' ')}] (not CANopen)"
        if msg.is_remote_frame:
            return "rtr", f"RTR 0x{cob:03X} dlc={msg.dlc}"
        function = cob & 0x780
        if cob == 0x000:
            return "nmt", self._nmt(data)
        if cob == 0x080:
            return "sync", "SYNC" + (f" counter={data[0]}" if data else "")
        if function == 0x080:
            return "emcy", self._emcy(node_id, data)
        if cob in self._pdos:
            return "pdo", self._pdo(cob, node_id, data)
        if function == 0x700:
            state = nmt_state_name(data[0] & 0x7F) if len(data) == 1 else f"bad length {len(data)}"
            return "heartbeat", f"HEARTBEAT {self._node(node_id)}: {state}"
        if function in (0x580, 0x600):
            return "sdo", self._sdo(function == 0x600, node_id, data)
        return "unknown", f"0x{cob:03X} [{data.hex(' ')}] (not part of the cobot's configuration)"

    @staticmethod
    def _nmt(data: bytes) -> str:
        if len(data) != 2:
            return f"NMT bad length {len(data)} [{data.hex(' ')}]"
        target = "all nodes" if data[1] == 0 else f"node {data[1]}"
        return f"NMT {_NMT_NAMES.get(data[0], f'command 0x{data[0]:02X}')} -> {target}"

    def _emcy(self, node_id: int, data: bytes) -> str:
        if len(data) != EMCY_STRUCT.size:
            return f"EMCY {self._node(node_id)}: bad length {len(data)} [{data.hex(' ')}]"
        code, register, extra = EMCY_STRUCT.unpack(data)
        desc = EmcyError(code, register, extra, 0.0).get_desc()
        return f"EMCY {self._node(node_id)}: code=0x{code:04X} ({desc}) register=0x{register:02X}"

    def _pdo(self, cob: int, node_id: int, data: bytes) -> str:
        kind, fields = self._pdos[cob]
        size = sum(f.size for f in fields)
        if len(data) != size:
            return f"{kind} {self._node(node_id)}: bad length {len(data)}, expected {size} [{data.hex(' ')}]"
        parts, offset = [], 0
        for f in fields:
            parts.append(f.format(data[offset : offset + f.size]))
            offset += f.size
        return f"{kind} {self._node(node_id)}: {' '.join(parts)}"

    def _sdo(self, request: bool, node_id: int, data: bytes) -> str:
        who = "SDO request to" if request else "SDO response from"
        if len(data) != 8:
            return f"{who} {self._node(node_id)}: bad length {len(data)}"
        spec = (_SDO_CLIENT if request else _SDO_SERVER).get(data[0] >> 5, f"specifier {data[0] >> 5}")
        text = f"{who} {self._node(node_id)}: {spec}"
        index, subindex = int.from_bytes(data[1:3], "little"), data[3]
        if spec in ("download", "upload", "abort"):
            text += f" 0x{index:04X}:{subindex:02X}"
        if spec == "abort":
            text += f" code=0x{int.from_bytes(data[4:8], 'little'):08X}"
        carries_value = spec == ("download" if request else "upload")
        if carries_value and data[0] & _EXPEDITED:
            size = 4 - ((data[0] >> 2) & 3) if data[0] & _SIZE_SPECIFIED else 4
            text += f" value={self._sdo_value(node_id, index, subindex, data[4 : 4 + size])}"
        return text

    def _sdo_value(self, node_id: int, index: int, subindex: int, raw: bytes) -> str:
        """An expedited SDO value as text, decoded with the object's type from the EDS when it is known."""
        obj = self._ods[node_id].get(index) if node_id in self._ods else None
        if isinstance(obj, (ODRecord, ODArray)):
            obj = obj.get(subindex)
        if isinstance(obj, ODVariable) and len(obj) == 8 * len(raw):
            value = obj.decode_raw(raw)
            return repr(value) if isinstance(value, (bytes, bytearray)) else str(value)  # bytes: b'...' as str()
        return str(int.from_bytes(raw, "little"))


def monitor(
    config: CobotBusConfig,
    joint_names: Sequence[str],
    duration: float,
    write: Callable[[str], None],
    listening: Callable[[], None] | None = None,
) -> Counter[str]:
    """Print every frame on the configured bus for `duration` seconds; returns frames per traffic class.

    `listening` is called once the bus is open (e.g. to start traffic that should be seen from its start).
    """
    decoder = FrameDecoder(config, joint_names)
    counts: Counter[str] = Counter()
    bus = open_bus(config.bus)
    if listening is not None:
        listening()
    start = time.monotonic()
    t0: float | None = None
    try:
        while (remaining := start + duration - time.monotonic()) > 0:
            msg = bus.recv(min(remaining, 0.1))
            if msg is None:
                continue
            t0 = msg.timestamp if t0 is None else t0
            kind, text = decoder.decode(msg)
            counts[kind] += 1
            write(f"{msg.timestamp - t0:10.4f}  0x{msg.arbitration_id:03X}  {text}")
    finally:
        bus.shutdown()
    return counts
