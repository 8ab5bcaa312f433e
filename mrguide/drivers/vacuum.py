"""Master side of the vacuum generator: LEMCOM-like manufacturer objects in the same SYNC/PDO cycle.

RPDO1 = 0x2000 command bits (vacuum on: byte 3 bit 0, blow-off: byte 1 bit 0, module 0 as on a COVAL
LEMCOM island). TPDO1 = 0x2020:01 vacuum level (0.1 kPa below atmosphere), 0x2001 part gripped,
0x2003 part lost (bit 0 each). Thresholds L1/h1 go to 0x2100/0x2101 at boot.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass

from canopen import RemoteNode
from canopen.objectdictionary import ODVariable
from canopen.pdo import PdoMap
from canopen.sdo.exceptions import SdoError

from mrguide.drivers.config import TimingConfig, VacuumNodeConfig
from mrguide.drivers.errors import BootError
from mrguide.drivers.objects import (
    DEVICE_TYPE,
    GRIP_HYSTERESIS,
    GRIP_THRESHOLD,
    PART_GRIPPED,
    PART_LOST,
    PRODUCER_HEARTBEAT_TIME,
    VACUUM_COMMAND,
    VACUUM_LEVEL,
)
from mrguide.drivers.od_values import node_id_of, od_int
from mrguide.drivers.pdo_setup import PdoEntries, map_pdos

logger = logging.getLogger(__name__)

RPDO_LAYOUT: dict[int, PdoEntries] = {1: ((VACUUM_COMMAND, 0),)}
TPDO_LAYOUT: dict[int, PdoEntries] = {1: ((VACUUM_LEVEL, 1), (PART_GRIPPED, 0), (PART_LOST, 0))}

#: 0x2000 bit for "vacuum on", module 0 (LEMCOM: byte 3 = vacuum, modules 0..7).
VACUUM_ON_BIT = 1 << 24
#: 0x2000 bit for "blow-off", module 0 (LEMCOM: byte 1 = blowing, modules 0..7).
BLOW_OFF_BIT = 1 << 8
#: Bit of module 0 in the 0x2001 / 0x2003 signal words.
MODULE0_BIT = 1
#: Unit of 0x2020 and 0x2100/0x2101 in kPa.
LEVEL_UNIT_KPA = 0.1


def command_bits(vacuum_on: bool, blow_off: bool) -> int:
    """Value of object 0x2000 for module 0."""
    return (VACUUM_ON_BIT if vacuum_on else 0) | (BLOW_OFF_BIT if blow_off else 0)


@dataclass(frozen=True)
class VacuumFeedback:
    """Latest TPDO contents of the vacuum generator."""

    level_kpa: float
    part_gripped: bool
    part_lost: bool
    sync_index: int
    received_at: float


class VacuumGenerator:
    """The vacuum generator on the bus, seen from the master."""

    def __init__(self, node: RemoteNode, config: VacuumNodeConfig, sync_index: Callable[[], int]) -> None:
        self.node = node
        self.node_id = node_id_of(node)
        self.config = config
        self._sync_index = sync_index
        self.feedback: VacuumFeedback | None = None
        self.rx_count = 0
        #: Command sent every cycle (set by the Cobot facade).
        self.vacuum_on = False
        self.blow_off = False
        self._rpdo: PdoMap | None = None

    @property
    def label(self) -> str:
        return f"node {self.node_id} (vacuum generator)"

    def configure(self, timing: TimingConfig) -> dict[int, int]:
        """Configure by SDO (node PRE-OPERATIONAL); returns {TPDO COB-ID: length}."""
        sdo = self.node.sdo
        sdo.RESPONSE_TIMEOUT = timing.sdo_timeout
        device_type_object = self.node.object_dictionary[DEVICE_TYPE]
        assert isinstance(device_type_object, ODVariable), "0x1000 is a variable (CiA 301)"
        expected_type = device_type_object.default
        try:
            device_type = sdo[DEVICE_TYPE].raw
            if device_type != expected_type:
                raise BootError(
                    f"{self.label}: device type 0x{device_type:08X}, EDS "
                    f"{self.config.eds} expects 0x{expected_type:08X}"
                )
            sdo[PRODUCER_HEARTBEAT_TIME].raw = timing.heartbeat_ms
            sdo[GRIP_THRESHOLD].raw = round(self.config.grip_threshold_kpa / LEVEL_UNIT_KPA)
            sdo[GRIP_HYSTERESIS].raw = round(self.config.grip_hysteresis_kpa / LEVEL_UNIT_KPA)
            rx = map_pdos(self.node.rpdo, RPDO_LAYOUT, self.label)
            tx = map_pdos(self.node.tpdo, TPDO_LAYOUT, self.label)
        except SdoError as exc:
            raise BootError(f"{self.label}: SDO configuration failed: {exc}") from exc
        self._rpdo = self.node.rpdo[1]
        (self._cmd_var,) = rx[1]
        self._level_var, self._gripped_var, self._lost_var = tx[1]
        self.node.tpdo[1].add_callback(self._on_status_pdo)
        logger.info(
            "%s configured: heartbeat %d ms, L1 %.1f kPa, h1 %.1f kPa",
            self.label,
            timing.heartbeat_ms,
            self.config.grip_threshold_kpa,
            self.config.grip_hysteresis_kpa,
        )
        return {self.node.tpdo[1].cob_id: len(self.node.tpdo[1].data)}

    def _on_status_pdo(self, pdo_map: PdoMap) -> None:
        self.feedback = VacuumFeedback(
            od_int(self._level_var.raw) * LEVEL_UNIT_KPA,
            bool(od_int(self._gripped_var.raw) & MODULE0_BIT),
            bool(od_int(self._lost_var.raw) & MODULE0_BIT),
            self._sync_index(),
            time.monotonic(),
        )
        self.rx_count += 1

    def send(self) -> int:
        """Transmit RPDO1 with the current command; returns the frame's data length."""
        assert self._rpdo is not None, "configure() first"
        self._cmd_var.raw = command_bits(self.vacuum_on, self.blow_off)
        self._rpdo.transmit()
        return len(self._rpdo.data)
