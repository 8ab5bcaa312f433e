"""Master side of a CiA 402 joint drive in cyclic synchronous position (CSP) mode, via canopen.

Boot configuration by SDO (heartbeat, interpolation period, following error, quick stop, mode 8, PDO
mapping), RPDO1 = controlword + target position, TPDO1 = statusword + position actual value,
TPDO2 = velocity actual value; all synchronous on every SYNC. The power state machine is driven one
controlword per cycle by `controlword_for`, never by blocking waits, so the control cycle keeps its pace.
"""

from __future__ import annotations

import enum
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

from canopen import RemoteNode
from canopen.pdo import PdoMap
from canopen.profiles.p402 import OperationMode, State402
from canopen.sdo.exceptions import SdoError

from mrguide.drivers.config import DriveConfig, TimingConfig
from mrguide.drivers.conversion import JointConversion
from mrguide.drivers.errors import BootError
from mrguide.drivers.objects import (
    CONTROLWORD,
    DEVICE_TYPE,
    FOLLOWING_ERROR_TIME_OUT,
    FOLLOWING_ERROR_WINDOW,
    INTERPOLATION_TIME_PERIOD,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    POSITION_ACTUAL_VALUE,
    PRODUCER_HEARTBEAT_TIME,
    QUICK_STOP_DECELERATION,
    QUICK_STOP_OPTION_CODE,
    STATUSWORD,
    SUPPORTED_DRIVE_MODES,
    TARGET_POSITION,
    VELOCITY_ACTUAL_VALUE,
)
from mrguide.drivers.od_values import node_id_of, od_int
from mrguide.drivers.pdo_setup import PdoEntries, map_pdos

logger = logging.getLogger(__name__)

CSP_MODE = OperationMode.CYCLIC_SYNCHRONOUS_POSITION
CSP_SUPPORTED_BIT = OperationMode.SUPPORTED["CYCLIC SYNCHRONOUS POSITION"]
#: Low word of object 0x1000 for devices following CiA 402.
CIA402_PROFILE = 402

RPDO_LAYOUT: dict[int, PdoEntries] = {1: ((CONTROLWORD, 0), (TARGET_POSITION, 0))}
TPDO_STATUS: PdoEntries = ((STATUSWORD, 0), (POSITION_ACTUAL_VALUE, 0))
TPDO_VELOCITY: PdoEntries = ((VELOCITY_ACTUAL_VALUE, 0),)

OPERATION_ENABLED = "OPERATION ENABLED"
QUICK_STOP_ACTIVE = "QUICK STOP ACTIVE"
SWITCH_ON_DISABLED = "SWITCH ON DISABLED"
FAULT_STATES = ("FAULT", "FAULT REACTION ACTIVE")
#: Controlword bit 7: a rising edge resets a fault.
FAULT_RESET_BIT = 0x80


def tpdo_layout(velocity: bool) -> dict[int, PdoEntries]:
    """TPDO layout of a drive: status and position, plus velocity in TPDO2 if wanted."""
    return {1: TPDO_STATUS, 2: TPDO_VELOCITY} if velocity else {1: TPDO_STATUS}


class PowerCommand(enum.Enum):
    """What the master wants from the power state machine of every drive."""

    DISABLE = "disable voltage"
    ENABLE = "enable operation"
    QUICK_STOP = "quick stop"
    FAULT_RESET = "fault reset"


def decode_state(statusword: int) -> str:
    """CiA 402 power state named by a statusword (canopen's State402 masks)."""
    for state, (mask, bits) in State402.SW_MASK.items():
        if statusword & mask == bits:
            return state
    return "UNKNOWN"


#: Next controlword on the way to OPERATION ENABLED, by current state (CiA 402 transitions 2, 3, 4, 16).
_ENABLE_STEP = {
    "NOT READY TO SWITCH ON": State402.CW_DISABLE_VOLTAGE,
    SWITCH_ON_DISABLED: State402.CW_SHUTDOWN,
    "READY TO SWITCH ON": State402.CW_SWITCH_ON,
    "SWITCHED ON": State402.CW_OPERATION_ENABLED,
    OPERATION_ENABLED: State402.CW_OPERATION_ENABLED,
    QUICK_STOP_ACTIVE: State402.CW_OPERATION_ENABLED,
}


def controlword_for(state: str, command: PowerCommand, previous: int) -> int:
    """Controlword for this cycle given the drive's state, the wanted command and last cycle's controlword.

    A fault is never reset by ENABLE: it needs FAULT_RESET, which toggles bit 7 so every attempt is a
    rising edge.
    """
    if command is PowerCommand.ENABLE:
        return _ENABLE_STEP.get(state, State402.CW_DISABLE_VOLTAGE)
    if command is PowerCommand.QUICK_STOP:
        return (
            State402.CW_QUICK_STOP if state in (OPERATION_ENABLED, QUICK_STOP_ACTIVE) else State402.CW_DISABLE_VOLTAGE
        )
    if command is PowerCommand.FAULT_RESET and state == "FAULT":
        return State402.CW_DISABLE_VOLTAGE if previous & FAULT_RESET_BIT else FAULT_RESET_BIT
    return State402.CW_DISABLE_VOLTAGE


def interpolation_period(period: float) -> tuple[int, int]:
    """Object 0x60C2 (value, index) with value * 10**index == period s, value <= 255."""
    for index in (-3, -4, -5, -6):
        value = period / 10.0**index
        if value <= 255 and abs(value - round(value)) < 1e-6:
            return round(value), index
    raise BootError(f"control period {period} s cannot be expressed in object 0x60C2")


@dataclass(frozen=True)
class DriveFeedback:
    """Latest TPDO contents of one drive, in drive units.

    `sync_index` is the last SYNC the master had sent when the TPDO arrived: the SYNC it answers as long as
    replies take less than one period (SYNC carries no counter, so later replies cannot be told apart).
    """

    statusword: int
    position: int
    velocity: int
    sync_index: int
    received_at: float

    @property
    def state(self) -> str:
        return decode_state(self.statusword)


class Cia402Drive:
    """One joint drive on the bus, seen from the master."""

    def __init__(
        self,
        node: RemoteNode,
        name: str,
        conversion: JointConversion,
        config: DriveConfig,
        sync_index: Callable[[], int],
    ) -> None:
        self.node = node
        self.node_id = node_id_of(node)
        self.name = name
        self.conversion = conversion
        self.config = config
        self._sync_index = sync_index
        #: Latest feedback (None until the first TPDO1 arrived).
        self.feedback: DriveFeedback | None = None
        #: Number of TPDO1 frames received (the master checks one arrives per SYNC).
        self.rx_count = 0
        self.last_controlword = 0
        #: Last target position sent (rad); NaN before the first RPDO.
        self.last_target = math.nan
        self._rpdo: PdoMap | None = None
        self._velocity = 0

    @property
    def label(self) -> str:
        return f"node {self.node_id} ({self.name})"

    def configure(self, timing: TimingConfig) -> dict[int, int]:
        """Configure the drive by SDO (it must be PRE-OPERATIONAL); returns {TPDO COB-ID: length}."""
        sdo = self.node.sdo
        sdo.RESPONSE_TIMEOUT = timing.sdo_timeout
        conv, cfg = self.conversion, self.config
        try:
            device_type = sdo[DEVICE_TYPE].raw
            if device_type & 0xFFFF != CIA402_PROFILE:
                raise BootError(f"{self.label}: device type 0x{device_type:08X} is not a CiA 402 device")
            if not sdo[SUPPORTED_DRIVE_MODES].raw & CSP_SUPPORTED_BIT:
                raise BootError(f"{self.label}: drive does not support cyclic synchronous position mode")
            sdo[PRODUCER_HEARTBEAT_TIME].raw = timing.heartbeat_ms
            value, index = interpolation_period(timing.control_period)
            sdo[INTERPOLATION_TIME_PERIOD][1].raw = value
            sdo[INTERPOLATION_TIME_PERIOD][2].raw = index
            sdo[FOLLOWING_ERROR_WINDOW].raw = min(conv.magnitude_to_counts(cfg.following_error_window), 0xFFFFFFFF)
            sdo[FOLLOWING_ERROR_TIME_OUT].raw = cfg.following_error_timeout_ms
            sdo[QUICK_STOP_OPTION_CODE].raw = cfg.quick_stop_option
            sdo[QUICK_STOP_DECELERATION].raw = min(conv.magnitude_to_counts(cfg.quick_stop_deceleration), 0xFFFFFFFF)
            sdo[MODES_OF_OPERATION].raw = CSP_MODE
            shown = sdo[MODES_OF_OPERATION_DISPLAY].raw
            if shown != CSP_MODE:
                raise BootError(f"{self.label}: mode of operation display is {shown}, expected {CSP_MODE} (CSP)")
            rx = map_pdos(self.node.rpdo, RPDO_LAYOUT, self.label)
            tx = map_pdos(self.node.tpdo, tpdo_layout(cfg.velocity_tpdo), self.label)
        except SdoError as exc:
            raise BootError(f"{self.label}: SDO configuration failed: {exc}") from exc
        self._rpdo = self.node.rpdo[1]
        self._cw_var, self._target_var = rx[1]
        self._sw_var, self._pos_var = tx[1]
        self.node.tpdo[1].add_callback(self._on_status_pdo)
        if 2 in tx:
            (self._vel_var,) = tx[2]
            self.node.tpdo[2].add_callback(self._on_velocity_pdo)
        logger.info(
            "%s configured: CSP, heartbeat %d ms, %s",
            self.label,
            timing.heartbeat_ms,
            "status+position+velocity TPDOs" if 2 in tx else "status+position TPDO",
        )
        return {self.node.tpdo[n].cob_id: len(self.node.tpdo[n].data) for n in tx}

    def _on_status_pdo(self, pdo_map: PdoMap) -> None:
        self.feedback = DriveFeedback(
            od_int(self._sw_var.raw), od_int(self._pos_var.raw), self._velocity, self._sync_index(), time.monotonic()
        )
        self.rx_count += 1

    def _on_velocity_pdo(self, pdo_map: PdoMap) -> None:
        self._velocity = od_int(self._vel_var.raw)
        fb = self.feedback
        if fb is not None:
            self.feedback = DriveFeedback(fb.statusword, fb.position, self._velocity, fb.sync_index, fb.received_at)

    def send(self, controlword: int, target: float) -> int:
        """Transmit RPDO1 (controlword, target position in rad); returns the frame's data length.

        The target must have passed `setpoint_guard.plan_rpdos` (finite, within the joint limits)."""
        assert self._rpdo is not None, "configure() first"
        self._cw_var.raw = controlword
        self._target_var.raw = self.conversion.to_counts(target)
        self._rpdo.transmit()
        self.last_controlword = controlword
        self.last_target = target
        return len(self._rpdo.data)

    def position_rad(self) -> float:
        assert self.feedback is not None
        return self.conversion.to_rad(self.feedback.position)
