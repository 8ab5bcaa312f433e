"""A simulated CANopen slave: canopen's LocalNode plus what it lacks for a cyclic device.

LocalNode gives the SDO server, the NMT slave with heartbeat producer and the EMCY producer. It does
not apply received RPDOs, send TPDOs on SYNC, reboot on NMT reset or consume heartbeats; this class
does, as a real device would: RPDOs received between two SYNCs are applied at the next SYNC, synchronous
TPDOs are sent on it. A producer configured in 0x1016 is supervised from its first heartbeat on; when it
falls silent for the consumer time the device sends EMCY 0x8130 and, if OPERATIONAL, enters
PRE-OPERATIONAL (the CiA 301 default error behaviour). As a device's CAN controller stamps a frame on arrival,
heartbeats are judged on the bus clock (the receiver's horizon): a simulator thread behind its queue does not
count a heartbeat still waiting in it as lost. Process data lives in `image` (keyed by
(index, subindex)) and is served to SDO reads and writes too.
"""

from __future__ import annotations

import logging
from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path

import canopen
from canopen import LocalNode
from canopen.objectdictionary import ODVariable

from mrguide.drivers.bus import BusReceiver
from mrguide.drivers.heartbeat import HEARTBEAT_ERROR, parse_consumer_heartbeat_entry
from mrguide.drivers.mock.faults import FaultInjector
from mrguide.drivers.mock.pdo_image import SYNC_TYPES, Key, PdoLayout, read_layouts
from mrguide.drivers.objects import (
    CONSUMER_HEARTBEAT_TIME,
    RPDO_COMMUNICATION,
    RPDO_MAPPING,
    TPDO_COMMUNICATION,
    TPDO_MAPPING,
)
from mrguide.drivers.od_values import node_id_of, od_int

logger = logging.getLogger(__name__)

NMT_RESET_NODE = 0x81
NMT_RESET_COMMUNICATION = 0x82
NMT_ENTER_PRE_OPERATIONAL = 0x80
#: Indices written back to their EDS values by NMT reset communication (CiA 301 communication area).
COMMUNICATION_AREA = range(0x1000, 0x2000)
#: Error register of a communication error: generic + communication bits (CiA 301 0x1001).
COMMUNICATION_ERROR_REGISTER = 0x11


@dataclass
class _ConsumedHeartbeat:
    """One producer the device supervises (an entry of 0x1016)."""

    timeout: float
    last: float | None = None  # bus time of the latest heartbeat; None = not yet started
    lost: bool = False


class SimulatedSlave(ABC):
    """Base of the simulated devices; subclasses define the process image and the SYNC behaviour."""

    def __init__(
        self, node_id: int, eds: Path, network: canopen.Network, receiver: BusReceiver, faults: FaultInjector
    ) -> None:
        self.node = LocalNode(node_id, str(eds))
        network.add_node(self.node)
        self.network = network
        self.receiver = receiver
        self.faults = faults
        self.image: dict[Key, int] = {}
        self._rpdos: list[PdoLayout] = []
        self._tpdos: list[PdoLayout] = []
        self._received: dict[int, bytes] = {}
        self._pdo_dirty = True
        self._consumed: dict[int, _ConsumedHeartbeat] = {}
        self.node.add_read_callback(self._on_read)
        self.node.add_write_callback(self._on_write)
        network.subscribe(0x000, self._on_nmt)
        receiver.expect(0x600 + node_id, (8,))

    @property
    def node_id(self) -> int:
        return node_id_of(self.node)

    @property
    def operational(self) -> bool:
        return self.node.nmt.state == "OPERATIONAL"

    @property
    def silent(self) -> bool:
        return self.faults.is_silent(self.node_id)

    # ---------------------------------------------------------------- subclass hooks

    @abstractmethod
    def reset_application(self) -> None:
        """Power-on values of the process image and the device's internal state."""

    def validate_write(self, key: Key, value: int) -> None:  # noqa: B027 - an optional hook: by default nothing
        """Raise canopen.SdoAbortedError to refuse an SDO write to a process-image object."""

    def after_write(self, index: int, subindex: int) -> None:  # noqa: B027 - an optional hook: by default nothing
        """Called after any SDO write (the value is stored)."""

    def on_nmt_state(self) -> None:  # noqa: B027 - an optional hook: by default nothing
        """Called after an NMT command changed the state (not on reset)."""

    # ---------------------------------------------------------------- NMT

    def power_on(self) -> None:
        """Boot as after switching power on: all objects at their EDS values, boot-up, PRE-OPERATIONAL."""
        self._reboot(NMT_RESET_NODE)

    def _reboot(self, command: int) -> None:
        if command == NMT_RESET_NODE:
            self.node.data_store.clear()
            self.reset_application()
        else:
            for index in [i for i in self.node.data_store if i in COMMUNICATION_AREA]:
                del self.node.data_store[index]
        self._pdo_dirty = True
        self._received.clear()
        self._reload_consumers()
        self.node.nmt.send_command(command)  # boot-up message
        self.node.nmt.send_command(NMT_ENTER_PRE_OPERATIONAL)  # starts the heartbeat per 0x1017
        logger.debug("node %d booted (%s)", self.node.id, "reset node" if command == NMT_RESET_NODE else "reset comm")

    def _on_nmt(self, can_id: int, data: bytearray, timestamp: float) -> None:
        command, target = data[0], data[1]
        if target not in (0, self.node.id) or self.silent:
            return
        if command in (NMT_RESET_NODE, NMT_RESET_COMMUNICATION):
            self._reboot(command)
            return
        if self.operational:
            self.refresh_pdos()  # PDO layouts take effect on entering OPERATIONAL
        self.on_nmt_state()

    # ---------------------------------------------------------------- object dictionary

    def value(self, key: Key) -> int:
        """Current value of an object: process image first, then the dictionary's stored/EDS value."""
        if key in self.image:
            return self.image[key]
        index, subindex = key
        obj = self.node.object_dictionary[index]
        var = obj if isinstance(obj, ODVariable) else obj[subindex]
        return od_int(var.decode_raw(self.node.get_data(index, subindex)))

    def _on_read(self, index: int, subindex: int, od: ODVariable) -> int | None:
        return self.image.get((index, subindex))

    def _on_write(self, index: int, subindex: int, od: ODVariable, data: bytes) -> None:
        if RPDO_COMMUNICATION <= index < 0x1C00:
            self._pdo_dirty = True
        key = (index, subindex)
        if key in self.image:
            value = od_int(od.decode_raw(data))  # the process image holds integer objects
            self.validate_write(key, value)
            self.image[key] = value
        self.node.data_store.setdefault(index, {})[subindex] = bytes(data)
        if index == CONSUMER_HEARTBEAT_TIME:
            self._reload_consumers()
        self.after_write(index, subindex)

    # ---------------------------------------------------------------- heartbeat consumer

    def _reload_consumers(self) -> None:
        """Follow the producers configured in 0x1016 (only sub-index 1 exists in the shipped EDS files)."""
        for producer_id in self._consumed:
            self.network.unsubscribe(0x700 + producer_id, self._on_consumed_heartbeat)
        self._consumed = {}
        parsed = parse_consumer_heartbeat_entry(self.value((CONSUMER_HEARTBEAT_TIME, 1)))
        if parsed is not None:
            producer_id, timeout = parsed
            self._consumed[producer_id] = _ConsumedHeartbeat(timeout)
            self.network.subscribe(0x700 + producer_id, self._on_consumed_heartbeat)
            self.receiver.expect(0x700 + producer_id, (1,))

    def _on_consumed_heartbeat(self, can_id: int, data: bytearray, timestamp: float) -> None:
        entry = self._consumed.get(can_id - 0x700)
        if entry is not None and not self.silent:
            entry.last, entry.lost = max(entry.last or timestamp, timestamp), False

    def check_heartbeats(self, now: float) -> None:
        """Heartbeat consumer time-out at bus time `now`: EMCY 0x8130 once per loss, and OPERATIONAL ->
        PRE-OPERATIONAL."""
        for producer_id, entry in self._consumed.items():
            if entry.lost or entry.last is None or now - entry.last <= entry.timeout:
                continue
            entry.lost = True
            logger.warning(
                "node %d: heartbeat of node %d lost (consumer time %.0f ms)",
                self.node.id,
                producer_id,
                entry.timeout * 1000,
            )
            self.node.emcy.send(HEARTBEAT_ERROR, COMMUNICATION_ERROR_REGISTER)
            if self.operational:
                self.node.nmt.send_command(NMT_ENTER_PRE_OPERATIONAL)
                self.on_nmt_state()

    # ---------------------------------------------------------------- PDOs

    def refresh_pdos(self) -> None:
        """Re-read the PDO configuration if the master changed it by SDO."""
        if not self._pdo_dirty:
            return
        for layout in self._rpdos:
            self.network.unsubscribe(layout.cob_id, self._on_rpdo)
        self._rpdos = read_layouts(self.node, RPDO_COMMUNICATION, RPDO_MAPPING)
        self._tpdos = [
            t for t in read_layouts(self.node, TPDO_COMMUNICATION, TPDO_MAPPING) if t.trans_type in SYNC_TYPES
        ]
        for layout in self._rpdos:
            self.network.subscribe(layout.cob_id, self._on_rpdo)
            self.receiver.expect(layout.cob_id, (layout.size,))
        self._pdo_dirty = False

    def _on_rpdo(self, can_id: int, data: bytearray, timestamp: float) -> None:
        if self.operational and not self.silent:
            self._received[can_id] = bytes(data)

    def apply_rpdos(self) -> None:
        """Copy the RPDOs received since the last SYNC into the process image."""
        for layout in self._rpdos:
            data = self._received.pop(layout.cob_id, None)
            if data is not None:
                self.image.update(layout.unpack(data))

    def transmit_tpdos(self, sync_count: int) -> None:
        """Send the synchronous TPDOs due at this SYNC."""
        for layout in self._tpdos:
            if sync_count % layout.trans_type == 0:
                self.network.send_message(layout.cob_id, layout.pack(self.value))
