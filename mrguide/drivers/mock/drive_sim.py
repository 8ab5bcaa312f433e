"""A simulated CiA 402 joint drive in cyclic synchronous position mode (the slave side).

Per SYNC: sample the joint from the plant into position/velocity actual value, apply the controlword to
the power state machine, and hand the plant the position its loop should track: the CSP target in
OPERATION ENABLED, the quick-stop ramp in QUICK STOP ACTIVE, the braked position otherwise. A following
error beyond 0x6065 for longer than 0x6066 faults the drive (EMCY 0x8611), as does an injected fault.
Modelled on the fake CiA 402 slave of ros2_canopen and the transition table of CiA 402.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import canopen
from canopen.sdo import SdoAbortedError

from mrguide.drivers.bus import BusReceiver
from mrguide.drivers.cia402 import CSP_MODE
from mrguide.drivers.conversion import JointConversion
from mrguide.drivers.mock.faults import FaultInjector
from mrguide.drivers.mock.pdo_image import Key
from mrguide.drivers.mock.slave import SimulatedSlave
from mrguide.drivers.objects import (
    CONTROLWORD,
    ERROR_CODE,
    ERROR_REGISTER,
    FOLLOWING_ERROR_TIME_OUT,
    FOLLOWING_ERROR_WINDOW,
    INTERPOLATION_TIME_PERIOD,
    MODES_OF_OPERATION,
    MODES_OF_OPERATION_DISPLAY,
    POSITION_ACTUAL_VALUE,
    QUICK_STOP_DECELERATION,
    QUICK_STOP_OPTION_CODE,
    STATUSWORD,
    TARGET_POSITION,
    VELOCITY_ACTUAL_VALUE,
)

logger = logging.getLogger(__name__)

NOT_READY = "NOT READY TO SWITCH ON"
SWITCH_ON_DISABLED = "SWITCH ON DISABLED"
READY = "READY TO SWITCH ON"
SWITCHED_ON = "SWITCHED ON"
OPERATION_ENABLED = "OPERATION ENABLED"
QUICK_STOP_ACTIVE = "QUICK STOP ACTIVE"
FAULT_REACTION_ACTIVE = "FAULT REACTION ACTIVE"
FAULT = "FAULT"

#: Statusword bits 0-6 per state (CiA 402).
_STATE_BITS = {
    NOT_READY: 0x0000,
    SWITCH_ON_DISABLED: 0x0040,
    READY: 0x0021,
    SWITCHED_ON: 0x0023,
    OPERATION_ENABLED: 0x0027,
    QUICK_STOP_ACTIVE: 0x0007,
    FAULT_REACTION_ACTIVE: 0x000F,
    FAULT: 0x0008,
}
SW_VOLTAGE_ENABLED = 0x0010
SW_REMOTE = 0x0200
SW_CSP_FOLLOWING = 0x1000
SW_FOLLOWING_ERROR = 0x2000
CW_FAULT_RESET = 0x80
#: Quick-stop option codes after which the drive stays in QUICK STOP ACTIVE (transition 16 allowed).
STAY_IN_QUICK_STOP = (5, 6, 7, 8)
EMCY_FOLLOWING_ERROR = 0x8611
#: Below this speed (rad/s) a quick-stopped joint counts as standing still.
STANDSTILL = 1e-3

_KEYS = {
    name: (index, 0)
    for name, index in (
        ("controlword", CONTROLWORD),
        ("statusword", STATUSWORD),
        ("mode", MODES_OF_OPERATION),
        ("mode_display", MODES_OF_OPERATION_DISPLAY),
        ("position", POSITION_ACTUAL_VALUE),
        ("velocity", VELOCITY_ACTUAL_VALUE),
        ("target", TARGET_POSITION),
        ("error_code", ERROR_CODE),
        ("error_register", ERROR_REGISTER),
    )
}


def next_power_state(state: str, controlword: int, previous: int, quick_stop_option: int) -> str:
    """Device-side CiA 402 transition on a controlword (automatic transitions are not handled here)."""
    if state == FAULT:
        return SWITCH_ON_DISABLED if controlword & CW_FAULT_RESET and not previous & CW_FAULT_RESET else FAULT
    if state in (NOT_READY, FAULT_REACTION_ACTIVE) or controlword & CW_FAULT_RESET:
        return state
    if controlword & 0x02 == 0:  # disable voltage: transitions 7, 9, 10, 12
        return SWITCH_ON_DISABLED if state in (READY, SWITCHED_ON, OPERATION_ENABLED, QUICK_STOP_ACTIVE) else state
    if controlword & 0x06 == 0x02:  # quick stop: 7, 10, 11
        if state == OPERATION_ENABLED:
            return QUICK_STOP_ACTIVE
        return SWITCH_ON_DISABLED if state in (READY, SWITCHED_ON) else state
    if controlword & 0x07 == 0x06:  # shutdown: 2, 6, 8
        return READY if state in (SWITCH_ON_DISABLED, SWITCHED_ON, OPERATION_ENABLED) else state
    if controlword & 0x0F == 0x07:  # switch on / disable operation: 3, 5
        return SWITCHED_ON if state in (READY, OPERATION_ENABLED) else state
    if controlword & 0x0F == 0x0F:  # enable operation: 3 then 4, 16
        if state == READY:
            return SWITCHED_ON
        if state == SWITCHED_ON or (state == QUICK_STOP_ACTIVE and quick_stop_option in STAY_IN_QUICK_STOP):
            return OPERATION_ENABLED
    return state


def error_register_for(code: int) -> int:
    """CiA 301 error register (0x1001) bits for an EMCY error code: generic plus the code's class."""
    classes = {0x2: 0x02, 0x3: 0x04, 0x4: 0x08}
    reg = 0x01 | classes.get(code >> 12, 0)
    if code & 0xFF00 == 0x8100:
        reg |= 0x10  # communication
    elif code & 0xFF00 == 0x8600 or code >> 12 == 0x6:
        reg |= 0x20  # device profile specific
    return reg


class SimulatedDrive(SimulatedSlave):
    """One CiA 402 servo drive: power state machine, CSP tracking, quick stop, following error, EMCY."""

    def __init__(
        self,
        node_id: int,
        eds: Path,
        network: canopen.Network,
        receiver: BusReceiver,
        faults: FaultInjector,
        conversion: JointConversion,
    ) -> None:
        super().__init__(node_id, eds, network, receiver, faults)
        self.conversion = conversion
        self.state = NOT_READY

    def reset_application(self) -> None:
        self.image = {key: 0 for key in _KEYS.values()}
        self.state = NOT_READY
        self._pending_fault: int | None = None
        self._prev_controlword = 0
        self._brake: float | None = None
        self._target: float | None = None
        self._ramp_velocity = 0.0
        self._following_time = 0.0
        self._following_error = False
        self._reload_parameters()

    def _reload_parameters(self) -> None:
        value, exponent = self.value((INTERPOLATION_TIME_PERIOD, 1)), self.value((INTERPOLATION_TIME_PERIOD, 2))
        self.interpolation_period = value * 10.0**exponent
        self._window = self.value((FOLLOWING_ERROR_WINDOW, 0))
        self._window_time = self.value((FOLLOWING_ERROR_TIME_OUT, 0)) / 1000.0
        self._quick_stop_option = self.value((QUICK_STOP_OPTION_CODE, 0))
        self._quick_stop_decel = self.value((QUICK_STOP_DECELERATION, 0)) / self.conversion.counts_per_rad

    def validate_write(self, key: Key, value: int) -> None:
        if key == _KEYS["mode"] and value not in (0, CSP_MODE):
            raise SdoAbortedError(0x06090030)  # value range of parameter exceeded

    def after_write(self, index: int, subindex: int) -> None:
        if index == MODES_OF_OPERATION:
            self.image[_KEYS["mode_display"]] = self.image[_KEYS["mode"]]
        elif index in (
            FOLLOWING_ERROR_WINDOW,
            FOLLOWING_ERROR_TIME_OUT,
            QUICK_STOP_OPTION_CODE,
            QUICK_STOP_DECELERATION,
            INTERPOLATION_TIME_PERIOD,
        ):
            self._reload_parameters()

    def on_nmt_state(self) -> None:
        if self.operational:
            return
        self.image[_KEYS["controlword"]] = 0  # no master: no command
        if self.state in (READY, SWITCHED_ON, OPERATION_ENABLED, QUICK_STOP_ACTIVE):
            logger.warning("node %d left OPERATIONAL while powered: disabling", self.node_id)
            self.state = SWITCH_ON_DISABLED
            self._update_statusword()

    def inject_fault(self, code: int) -> None:
        """Fault at the next SYNC with EMCY error code `code` (cleared by a fault reset)."""
        self._pending_fault = code

    def cycle(self, q: float, v: float, dt: float) -> float:
        """One SYNC: sample the joint, run the state machine on the controlword; returns the plant target (rad)."""
        conv, image = self.conversion, self.image
        image[_KEYS["position"]] = conv.to_counts(q + self.faults.position_error(self.node_id))
        image[_KEYS["velocity"]] = conv.velocity_to_counts(v)
        controlword = image[_KEYS["controlword"]]
        if self.state == NOT_READY:
            self.state = SWITCH_ON_DISABLED  # transition 1: self-test done
        elif self.state == FAULT_REACTION_ACTIVE:
            self.state = FAULT  # transition 14: brake applied
        elif self._pending_fault is not None and self.state != FAULT:
            self._enter_fault(self._pending_fault)
        elif self._following_error_expired(q, dt):
            self._enter_fault(EMCY_FOLLOWING_ERROR)
        else:
            self._transition(
                next_power_state(self.state, controlword, self._prev_controlword, self._quick_stop_option), q, v
            )
        self._prev_controlword = controlword
        target = self._plant_target(q, v, dt)
        self._update_statusword()
        return target

    def _transition(self, new: str, q: float, v: float) -> None:
        old, self.state = self.state, new
        if new == old:
            return
        logger.debug("node %d: %s -> %s", self.node_id, old, new)
        if new == QUICK_STOP_ACTIVE:
            self._ramp_velocity = v
            self._target = q if self._target is None else self._target
        if new == SWITCH_ON_DISABLED and old == FAULT:
            self.image[_KEYS["error_code"]] = 0
            self.image[_KEYS["error_register"]] = 0
            self.node.emcy.reset()
        if new == OPERATION_ENABLED:
            self._target = None
            self._following_time = 0.0

    def _enter_fault(self, code: int) -> None:
        register = error_register_for(code)
        logger.info("node %d: fault, EMCY 0x%04X", self.node_id, code)
        self.state = FAULT_REACTION_ACTIVE
        self._pending_fault = None
        self.image[_KEYS["error_code"]] = code
        self.image[_KEYS["error_register"]] = register
        self.node.emcy.send(code, register)

    def _following_error_expired(self, q: float, dt: float) -> bool:
        """Position tracked during the last period vs where the joint is now, against 0x6065/0x6066."""
        if self.state != OPERATION_ENABLED or self._target is None:
            self._following_error = False
            return False
        error = abs(self._target - q) * self.conversion.counts_per_rad
        self._following_error = error > self._window
        self._following_time = self._following_time + dt if self._following_error else 0.0
        return self._following_time > self._window_time

    def _plant_target(self, q: float, v: float, dt: float) -> float:
        if self.state == OPERATION_ENABLED and self.image[_KEYS["mode_display"]] == CSP_MODE:
            self._brake = None
            self._target = self.conversion.to_rad(self.image[_KEYS["target"]])
            return self._target
        if self.state == QUICK_STOP_ACTIVE:
            return self._quick_stop_ramp(v, dt)
        if self._brake is None:
            self._brake = q if self._target is None else self._target
        self._target = None
        return self._brake

    def _quick_stop_ramp(self, v: float, dt: float) -> float:
        assert self._target is not None
        speed = max(abs(self._ramp_velocity) - self._quick_stop_decel * dt, 0.0)
        self._ramp_velocity = math.copysign(speed, self._ramp_velocity)
        self._target += self._ramp_velocity * dt
        if speed == 0.0 and abs(v) < STANDSTILL and self._quick_stop_option not in STAY_IN_QUICK_STOP:
            self.state = SWITCH_ON_DISABLED  # transition 12 after standstill
            self._brake, self._target = self._target, None
            return self._brake
        return self._target

    def _update_statusword(self) -> None:
        sw = _STATE_BITS[self.state] | SW_REMOTE
        if self.state in (SWITCHED_ON, OPERATION_ENABLED, QUICK_STOP_ACTIVE, FAULT_REACTION_ACTIVE):
            sw |= SW_VOLTAGE_ENABLED
        if self.state == OPERATION_ENABLED and self.image[_KEYS["mode_display"]] == CSP_MODE:
            sw |= SW_CSP_FOLLOWING
        if self._following_error:
            sw |= SW_FOLLOWING_ERROR
        self.image[_KEYS["statusword"]] = sw

    def hold(self, q: float) -> float:
        """A dead (silent) drive: brake engaged where the joint is."""
        if self._brake is None:
            self._brake = q
        return self._brake
