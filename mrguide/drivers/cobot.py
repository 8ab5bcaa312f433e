"""The `Cobot` facade: what the deploy runtime uses to drive the arm and the vacuum gripper over CAN.

The work is done by its parts, which share one `CobotCore` (cobot_core.py): `boot` opens the bus, boots
and configures the nodes and tears everything down again; `control_loop` runs the SYNC cycle in a thread
of its own; `supervision` watches heartbeats, PDO feedback, EMCY/statusword faults and the bus and latches
the first fault (all drives get quick stop, streaming stops, and the next facade call raises that fault).
Setpoints are validated before they enter the queue (`setpoint_guard.setpoint_problem`, a pure function),
and every RPDO's target once more right before it is sent, so no non-finite or out-of-limit target reaches
the bus by any path. `CobotInterface` (interface.py) is what the runtime may rely on.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

import numpy as np

from mrguide.drivers import boot, supervision
from mrguide.drivers.cia402 import OPERATION_ENABLED, SWITCH_ON_DISABLED, PowerCommand
from mrguide.drivers.cobot_core import CobotCore
from mrguide.drivers.cobot_state import CobotStatus, CycleSample, DriverStats, JointState, VacuumState
from mrguide.drivers.config import CobotBusConfig
from mrguide.drivers.control_loop import ControlLoop
from mrguide.drivers.errors import BusError, DriverError, NodeLostError, NotReadyError, SetpointError
from mrguide.drivers.heartbeat import OPERATIONAL, nmt_state_name
from mrguide.drivers.setpoint_guard import setpoint_array, setpoint_problem
from mrguide.robot import RobotSpec, load_robot

logger = logging.getLogger(__name__)

#: Control periods past the queue's depth that `stream` waits for room before it calls the cycle stalled.
STALL_CYCLES = 25


class Cobot:
    """Joint drives + vacuum generator of one cobot on one CAN bus.

    Typical use::

        with Cobot(load_cobot_bus_config("configs/devices/cobot_bus.toml")) as cobot:   # connect()
            cobot.enable()
            for q in trajectory:            # one setpoint (rad) per control period
                cobot.stream(q)             # blocks while the setpoint queue is full
            cobot.set_vacuum(True)
            state = cobot.joint_state()
        # disconnect(): quick stop, disable, NMT pre-operational, bus closed
    """

    def __init__(self, config: CobotBusConfig | None = None, robot: RobotSpec | None = None) -> None:
        self._core = CobotCore(config or CobotBusConfig(), robot or load_robot())
        self._loop = ControlLoop(self._core)
        self.config = self._core.config
        self.robot = self._core.robot
        self.limits = self._core.limits
        self.joint_names = self._core.joint_names
        self.period = self._core.period
        self._underruns_logged = 0  # the underrun count `stream` last logged

    @property
    def setpoint_queue_depth(self) -> int:
        """Setpoints `stream` buffers ahead of the bus before it blocks."""
        return self.config.timing.setpoint_queue_depth

    @property
    def feedback_tolerance_cycles(self) -> int:
        """Cycles without new feedback before the driver latches a fault (timing.max_missed_feedback)."""
        return self.config.timing.max_missed_feedback

    # ------------------------------------------------------------------ lifecycle

    def connect(self) -> None:
        """Open the bus, boot and configure every node (NMT + SDO), start the SYNC cycle.

        Returns once every node sends PDO feedback. Raises ConfigError, BusError or BootError.
        """
        boot.connect(self._core, self._loop)

    def disconnect(self) -> None:
        """Quick-stop moving drives, disable them, put every node in PRE-OPERATIONAL and close the bus.

        The vacuum command is left as it is (a held part stays held); call set_vacuum(False) first to release.
        Never raises: whatever fails on the way is logged, and the NMT commands and closing the bus still happen.
        """
        boot.disconnect(self._core, self._loop)

    def __enter__(self) -> Cobot:
        self.connect()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.disconnect()

    # ------------------------------------------------------------------ commands

    def enable(self, timeout: float | None = None) -> None:
        """Bring every drive to OPERATION ENABLED, holding the current position; then `stream` is allowed."""
        core = self._core
        timeout = self.config.timing.enable_timeout if timeout is None else timeout
        with core.lock.bounded():
            core.require_connected()
            core.raise_fault()
            if core.motion:
                return
            outside = [
                f"{n} at {x:.4f} rad (limits {lo:.3f}..{hi:.3f})"
                for n, x, lo, hi in zip(self.joint_names, core.positions(), self.limits.q_lower, self.limits.q_upper)
                if not lo <= x <= hi
            ]
            if outside:
                raise NotReadyError(f"cannot enable: joints outside their limits: {'; '.join(outside)}")
            core.command = PowerCommand.ENABLE
        core.wait_for(lambda: core.motion or core.fault is not None, timeout)
        with core.lock.bounded():
            core.raise_fault()
            if not core.motion:
                core.command = PowerCommand.DISABLE
                states = ", ".join(f"{d.label}: {core.state(d)}" for d in core.drives)
                raise DriverError(f"drives did not reach {OPERATION_ENABLED} within {timeout} s ({states})")
        logger.info("drives enabled (CSP)")

    def stream(self, q: np.ndarray, timeout: float | None = None) -> None:
        """Queue the next joint setpoint (rad, robot joint order); one setpoint is sent per control cycle.

        Refused with SetpointError (nothing queued, nothing sent) unless finite, within the joint limits
        and at most v_max * period away from the previous setpoint. Blocks while the queue is full; raises
        the latched fault if one occurs, NotReadyError if the drives are not enabled, DriverError if the
        control cycle stalls (queue still full after `timeout`) or hangs (driver lock held). The default
        timeout is the queue's depth plus `STALL_CYCLES` control periods, or plus `timing.max_missed_feedback`
        where the bus config tolerates more (the simulated devices on a shared PC): a control thread that
        skips cycles is judged no stricter than the feedback it would miss.
        """
        core = self._core
        depth = self.setpoint_queue_depth
        if timeout is None:
            timeout = self.period * (depth + max(STALL_CYCLES, self.config.timing.max_missed_feedback))
        try:
            q = setpoint_array(q)
        except (TypeError, ValueError) as exc:
            core.refused += 1
            raise SetpointError(f"setpoint is not an array of joint positions: {exc}") from exc
        underruns = core.underruns  # counted by the control thread, logged here (no I/O there, nor under the lock)
        if underruns > self._underruns_logged:
            logger.warning("setpoint queue ran dry while moving: the last setpoint was held (%d so far)", underruns)
        self._underruns_logged = underruns  # (lower after a reconnect: the counters start again)
        end = time.monotonic() + timeout
        while True:
            with core.lock.bounded():
                core.require_streaming()
                if len(core.queue) < depth:
                    reference = core.queue[-1] if core.queue else core.hold
                    assert reference is not None
                    problem = setpoint_problem(q, reference, self.limits, self.period, self.joint_names)
                    if problem:
                        core.refused += 1
                        raise SetpointError(f"setpoint refused: {problem}")
                    core.queue.append(q)
                    return
                core.space.clear()  # under the lock: a setpoint taken from here on sets it again
            remaining = end - time.monotonic()
            if remaining <= 0:
                raise DriverError(f"setpoint queue still full after {timeout:.3f} s: the control cycle is stalled")
            core.space.wait(remaining)

    def set_vacuum(self, on: bool, blow_off: bool = False) -> None:
        """Command the vacuum generator (sent every cycle). Works during a drive fault, so a part stays held."""
        if not isinstance(on, (bool, np.bool_)) or not isinstance(blow_off, (bool, np.bool_)):
            raise SetpointError(f"vacuum command must be booleans, got on={on!r}, blow_off={blow_off!r}")
        if on and blow_off:
            raise SetpointError("vacuum and blow-off cannot be commanded at the same time")
        core = self._core
        with core.lock.bounded():
            core.require_connected()
            assert core.vacuum is not None
            fault = core.fault
            if isinstance(fault, BusError) or (
                isinstance(fault, NodeLostError) and fault.node_id == self.config.vacuum.node_id
            ):
                raise fault
            core.vacuum.vacuum_on, core.vacuum.blow_off = bool(on), bool(blow_off)

    def stop(self) -> None:
        """Quick stop: every enabled drive decelerates on its quick-stop ramp; queued setpoints are dropped.

        Never hangs: the request is posted without the lock and carried out here or by the control thread
        at its next cycle. If the control thread holds the lock (hung), this logs an error and returns; the
        request waits for it, and devices consuming the master's heartbeat disable themselves meanwhile.
        """
        if self._core.network is None:
            return
        if supervision.quick_stop(self._core):
            logger.info("quick stop commanded")
        else:
            logger.error(
                "quick stop requested, but the control thread has held the driver lock for %.1f s: it is hung",
                self._core.lock.timeout,
            )

    def reset_faults(self, timeout: float | None = None) -> None:
        """Fault reset (controlword bit 7) on faulted drives, disable the others; clears the latched fault.

        Afterwards every drive is SWITCH ON DISABLED and `enable()` may be called again. Raises if a node is
        still silent or not OPERATIONAL (reconnect then), or a drive stays in FAULT.
        """
        core = self._core
        timeout = self.config.timing.enable_timeout if timeout is None else timeout
        with core.lock.bounded():
            core.require_connected()
            if isinstance(core.fault, BusError):
                raise core.fault
            core.command = PowerCommand.FAULT_RESET
            supervision.halt(core)
        hb, ids = core.hb, self.config.node_ids
        assert hb is not None
        done = core.wait_for(
            lambda: (
                all(core.state(d) == SWITCH_ON_DISABLED for d in core.drives)
                and not hb.expired()
                and hb.all_in_state(OPERATIONAL, ids)
            ),
            timeout,
        )
        with core.lock.bounded():
            if not done:
                core.command = PowerCommand.DISABLE
                problems = [f"{d.label}: {core.state(d)}" for d in core.drives if core.state(d) != SWITCH_ON_DISABLED]
                problems += [f"{core.label(n)}: no heartbeat for {age:.2f} s" for n, age in hb.expired()]
                problems += [
                    f"{core.label(n)}: NMT {nmt_state_name(hb.state(n))} (reconnect)"
                    for n in ids
                    if hb.state(n) != OPERATIONAL
                ]
                raise DriverError(f"fault reset did not complete within {timeout} s: {'; '.join(problems)}")
            if core.fault is not None:
                logger.info("fault cleared: %s", core.fault)
            core.fault = None
            core.fault_at = None
            core.command = PowerCommand.DISABLE
            core.misses = dict.fromkeys(core.misses, 0)

    def check(self) -> None:
        """Raise the latched fault, if any (for runtimes that poll)."""
        with self._core.lock.bounded():
            self._core.raise_fault()

    # ------------------------------------------------------------------ state

    @property
    def setpoint(self) -> np.ndarray:
        """Last accepted joint setpoint (rad): where the next streamed setpoint must start from."""
        core = self._core
        with core.lock.bounded():
            core.require_streaming()
            assert core.hold is not None
            return (core.queue[-1] if core.queue else core.hold).copy()

    def joint_state(self) -> JointState:
        """Latest joint positions (rad), velocities (rad/s) and drive states."""
        core = self._core
        with core.lock.bounded():
            core.require_connected()
            drives = list(core.drives)
            latest = [d.feedback for d in drives]
        fbs = [fb for fb in latest if fb is not None]
        if len(fbs) < len(latest):
            raise NotReadyError("no joint feedback yet")
        now = time.monotonic()
        return JointState(
            positions=np.array([d.conversion.to_rad(fb.position) for d, fb in zip(drives, fbs)]),
            velocities=np.array([d.conversion.velocity_to_rad(fb.velocity) for d, fb in zip(drives, fbs)]),
            drive_states=tuple(fb.state for fb in fbs),
            sync_index=min(fb.sync_index for fb in fbs),
            age=now - min(fb.received_at for fb in fbs),
        )

    def vacuum_state(self) -> VacuumState:
        """Latest vacuum level (kPa below atmosphere), part-gripped/lost flags and the command being sent."""
        core = self._core
        with core.lock.bounded():
            core.require_connected()
            vac = core.vacuum
            assert vac is not None
            fb = vac.feedback
            if fb is None:
                raise NotReadyError("no vacuum feedback yet")
            return VacuumState(
                fb.level_kpa,
                fb.part_gripped,
                fb.part_lost,
                vac.vacuum_on,
                vac.blow_off,
                time.monotonic() - fb.received_at,
            )

    def status(self) -> CobotStatus:
        """Everything a supervisor or a report wants to know, in one snapshot."""
        core = self._core
        hb, ids = core.hb, self.config.node_ids
        connected = core.network is not None
        return CobotStatus(
            connected=connected,
            enabled=core.motion,
            drive_states={d.name: core.state(d) for d in core.drives},
            nmt_states={n: nmt_state_name(hb.state(n) if hb else None) for n in ids},
            fault=core.fault,
            fault_at=core.fault_at,
            heartbeat_lost=tuple(n for n, _ in hb.expired()) if (hb and connected) else (),
            stats=self.stats(),
        )

    def stats(self) -> DriverStats:
        core = self._core
        cyc = core.cycle_stats.summary()
        rx = core.receiver.stats() if core.receiver else None
        return DriverStats(
            cycles=cyc.cycles,
            missed_cycles=cyc.missed,
            lateness_p50=cyc.lateness_p50,
            lateness_p99=cyc.lateness_p99,
            lateness_max=cyc.lateness_max,
            work_p99=cyc.work_p99,
            work_max=cyc.work_max,
            work_overruns=cyc.overruns,
            frames_tx=core.frames_tx,
            bits_tx=core.bits_tx,
            frames_rx=rx.frames_rx if rx else 0,
            bits_rx=rx.bits_rx if rx else 0,
            lost_feedback=core.lost_feedback,
            underruns=core.underruns,
            refused_setpoints=core.refused,
            unknown_frames=rx.unknown_id + rx.remote_frames if rx else 0,
            bad_length_frames=rx.bad_length if rx else 0,
            error_frames=rx.error_frames if rx else 0,
            emcy_received=core.emcy_count,
            misses=cyc.misses,
        )

    def add_cycle_observer(self, observer: Callable[[CycleSample], None]) -> None:
        """Call `observer` from the control thread after every cycle (keep it fast). An exception in it
        latches a fault (quick stop): observers are monitors, and a monitor that fails must not fail open."""
        self._core.observers.append(observer)

    def remove_cycle_observer(self, observer: Callable[[CycleSample], None]) -> None:
        self._core.observers.remove(observer)
