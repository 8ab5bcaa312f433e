"""The `Cobot` facade: what the deploy runtime uses to drive the arm and the vacuum gripper over CAN.

One control thread runs the SYNC cycle on absolute monotonic deadlines: at each deadline it sends SYNC,
then one RPDO per drive (controlword + target position) and one to the vacuum generator; the devices
apply them at the next SYNC. The same thread sends the master's heartbeat, which every device consumes
(0x1016), so a hung control thread or a dead PC disables the drives without the master's help. It also
supervises heartbeats, PDO feedback, EMCY/statusword faults and the bus, and latches the first fault:
all drives get quick stop, streaming stops, and the next facade call raises that fault. Setpoints are
validated before they enter the queue, and every RPDO's target once more right before it is sent
(`setpoint_guard`), so no non-finite or out-of-limit target reaches the bus by any path.
"""

from __future__ import annotations

import logging
import threading
import time
from collections import deque
from collections.abc import Callable
from functools import partial

import can
import canopen
import numpy as np
from canopen import RemoteNode
from canopen.emcy import EmcyError
from canopen.sdo.exceptions import SdoError

from mrguide.config import ConfigError
from mrguide.drivers.bus import BusReceiver, frame_bits, open_bus
from mrguide.drivers.cia402 import (FAULT_STATES, OPERATION_ENABLED, QUICK_STOP_ACTIVE, SWITCH_ON_DISABLED,
                                    Cia402Drive, PowerCommand)
from mrguide.drivers.cobot_state import CobotStatus, CycleSample, DriverStats, JointState, VacuumState
from mrguide.drivers.config import CobotBusConfig, eds_path, resolve_limits
from mrguide.drivers.conversion import JointConversion
from mrguide.drivers.cycle import CycleStats, CycleTimer, Tick
from mrguide.drivers.driver_lock import DriverLock
from mrguide.drivers.errors import (BootError, BusError, BusOffError, DeviceFaultError, DriverError,
                                    FeedbackLostError, HeartbeatLostError, NodeLostError, NotReadyError,
                                    SetpointError)
from mrguide.drivers.heartbeat import OPERATIONAL, HeartbeatConsumer, nmt_state_name
from mrguide.drivers.nmt import (NMT_RESET_COMMUNICATION, NMT_START, close_network, send_nmt, set_master_consumer,
                                 sign_off)
from mrguide.drivers.realtime import make_current_thread_realtime
from mrguide.drivers.setpoint_guard import plan_rpdos, setpoint_array, setpoint_problem
from mrguide.drivers.vacuum import BLOW_OFF_BIT, VACUUM_ON_BIT, VacuumGenerator
from mrguide.robot import RobotSpec, load_robot

logger = logging.getLogger(__name__)

#: A setpoint step above this fraction of v_max * period means the arm is moving (for underrun counting).
MOVING_FRACTION = 0.01


def _load_node(node_id: int, eds: str) -> RemoteNode:
    path = eds_path(eds)
    try:
        return RemoteNode(node_id, str(path))
    except Exception as exc:  # configparser, KeyError, ValueError... from a third-party file format
        raise ConfigError(f"EDS file {path} cannot be read for node {node_id}: {exc}") from exc


class Cobot:
    """Joint drives + vacuum generator of one cobot on one CAN bus.

    Typical use::

        with Cobot(load_cobot_bus_config("configs/cobot_bus.toml")) as cobot:   # connect()
            cobot.enable()
            for q in trajectory:            # one setpoint (rad) per control period
                cobot.stream(q)             # blocks while the setpoint queue is full
            cobot.set_vacuum(True)
            state = cobot.joint_state()
        # disconnect(): quick stop, disable, NMT pre-operational, bus closed
    """

    def __init__(self, config: CobotBusConfig | None = None, robot: RobotSpec | None = None) -> None:
        self.config = config or CobotBusConfig()
        self.robot = robot or load_robot()
        self.limits = resolve_limits(self.config, self.robot)
        self.joint_names = self.robot.joint_names
        self.period = self.config.timing.control_period
        self._max_step = self.limits.v_max * self.period
        # rounded down: the master's heartbeat never comes later than the period the devices expect
        self._heartbeat_cycles = max(1, int(self.config.timing.heartbeat_period / self.period + 1e-9))
        self._lock = DriverLock()
        #: Set whenever the setpoint queue gets room or streaming ends (wakes a blocked `stream`).
        self._space = threading.Event()
        self._queue: deque[np.ndarray] = deque()
        self._network: canopen.Network | None = None
        self._receiver: BusReceiver | None = None
        self._hb: HeartbeatConsumer | None = None
        self._drives: list[Cia402Drive] = []
        self._vacuum: VacuumGenerator | None = None
        self._thread: threading.Thread | None = None
        self._stop_thread = threading.Event()
        self._observers: list[Callable[[CycleSample], None]] = []
        self._reset_run_state()

    def _reset_run_state(self) -> None:
        self._command = PowerCommand.DISABLE
        self._motion = False
        self._hold: np.ndarray | None = None
        self._moving = False
        self._fault: DriverError | None = None
        self._fault_at: float | None = None
        self._sync_index = 0
        self._sync_sent = False
        self._heartbeat_due = 1
        self._last_rx: dict[int, int] = {}
        self._misses: dict[int, int] = {}
        self._lost_logged: set[int] = set()
        self._cycle_stats = CycleStats()
        self._frames_tx = self._bits_tx = 0
        self._lost_feedback = self._underruns = self._refused = self._emcy_count = 0
        self._queue.clear()
        self._lock.discard_requests()

    # ------------------------------------------------------------------ lifecycle

    def connect(self) -> None:
        """Open the bus, boot and configure every node (NMT + SDO), start the SYNC cycle.

        Returns once every node sends PDO feedback. Raises ConfigError, BusError or BootError.
        """
        if self._network is not None:
            raise NotReadyError("already connected")
        self._reset_run_state()
        cfg = self.config
        nodes = [_load_node(j.node_id, cfg.drives.eds) for j in cfg.joints]
        vacuum_node = _load_node(cfg.vacuum.node_id, cfg.vacuum.eds)
        network = canopen.Network(open_bus(cfg.bus))
        receiver = BusReceiver(network, "master", cfg.timing.realtime_priority)
        hb = HeartbeatConsumer(cfg.timing.heartbeat_timeout)
        self._drives = [Cia402Drive(node, name, JointConversion.from_config(joint), cfg.drives, self._current_sync)
                        for node, name, joint in zip(nodes, self.joint_names, cfg.joints)]
        self._vacuum = VacuumGenerator(vacuum_node, cfg.vacuum, self._current_sync)
        receiver.expect(0x000, (2,))  # NMT commands from another master: legal, canopen tracks them
        for node in [*nodes, vacuum_node]:
            network.add_node(node)
            hb.watch(node)
            node.emcy.add_callback(partial(self._on_emcy, node.id))
            receiver.expect(0x700 + node.id, (1,))
            receiver.expect(0x080 + node.id, (8,))
            receiver.expect(0x580 + node.id, (8,))
        self._network, self._receiver, self._hb = network, receiver, hb
        try:
            receiver.start()
            self._boot()
            self._stop_thread = threading.Event()  # one per thread: a thread left behind never resumes
            self._thread = threading.Thread(target=self._run, args=(self._stop_thread,), name="mrguide-can-cycle",
                                            daemon=True)
            self._thread.start()
            devices = [*self._drives, self._vacuum]
            if not self._wait_for(lambda: all(d.feedback is not None for d in devices), self.config.timing.boot_timeout):
                silent = [d.label for d in devices if d.feedback is None]
                raise BootError(f"no PDO feedback from {', '.join(silent)} after NMT start")
            self._raise_fault()
        except can.CanError as exc:
            self._teardown()
            raise BusError(f"CAN error during boot on {self._bus_name()}: {exc}") from exc
        except BaseException:
            self._teardown()
            raise
        logger.info("cobot connected on %s: %d drives + vacuum generator, %.1f ms cycle", self._bus_name(),
                    len(self._drives), self.period * 1000)

    def _boot(self) -> None:
        timing = self.config.timing
        assert self._hb is not None and self._receiver is not None and self._vacuum is not None
        devices = [*self._drives, self._vacuum]
        self._hb.expect_bootup()
        for dev in devices:
            send_nmt(dev.node.network, NMT_RESET_COMMUNICATION, dev.node.id)
        missing = self._hb.wait_bootup(timing.boot_timeout)
        if missing:
            labels = ", ".join(self._label(n) for n in missing)
            raise BootError(f"no boot-up message from {labels} within {timing.boot_timeout} s after NMT reset "
                            f"communication on {self._bus_name()}; check power, wiring, node IDs and bit rate")
        for dev in devices:
            for cob_id, length in dev.configure(timing).items():
                self._receiver.expect(cob_id, (length,))
            if self.config.master.heartbeat:
                try:
                    set_master_consumer(dev.node, self.config.master.node_id, timing.heartbeat_timeout_ms)
                except SdoError as exc:
                    raise BootError(f"{dev.label}: cannot make it consume the master's heartbeat (0x1016:01): {exc}; "
                                    "set [master] heartbeat = false for devices without 0x1016") from exc
        self._vacuum.vacuum_on, self._vacuum.blow_off = self._vacuum_command_on_device()
        self._hb.arm()
        for dev in devices:
            send_nmt(dev.node.network, NMT_START, dev.node.id)
        ids = self.config.node_ids
        if not self._wait_for(lambda: self._hb.all_in_state(OPERATIONAL, ids), timing.boot_timeout):
            states = ", ".join(f"{self._label(n)}: {nmt_state_name(self._hb.state(n))}" for n in ids
                               if self._hb.state(n) != OPERATIONAL)
            raise BootError(f"nodes did not report OPERATIONAL by heartbeat after NMT start: {states}")

    def _vacuum_command_on_device(self) -> tuple[bool, bool]:
        """Keep whatever the vacuum generator is doing (a held part must not drop on reconnect)."""
        assert self._vacuum is not None
        try:
            bits = self._vacuum.node.sdo[0x2000].raw
        except SdoError as exc:
            raise BootError(f"{self._vacuum.label}: cannot read vacuum command 0x2000: {exc}") from exc
        return bool(bits & VACUUM_ON_BIT), bool(bits & BLOW_OFF_BIT)

    def disconnect(self) -> None:
        """Quick-stop moving drives, disable them, put every node in PRE-OPERATIONAL and close the bus.

        The vacuum command is left as it is (a held part stays held); call set_vacuum(False) first to release.
        Never raises: whatever fails on the way is logged, and the NMT commands and closing the bus still happen.
        """
        if self._network is None:
            return
        try:
            self._stop_and_disable()
        except Exception:  # noqa: BLE001 - the teardown below must happen whatever went wrong
            logger.exception("disconnect: stopping and disabling the drives failed; tearing down anyway")
        finally:
            self._teardown()
        logger.info("cobot disconnected")

    def _stop_and_disable(self) -> None:
        """Quick-stop moving drives, wait until they are disabled, end the devices' supervision of the master."""
        if isinstance(self._fault, BusError) or self._thread is None or not self._thread.is_alive():
            return  # nothing can be sent
        powered = (OPERATION_ENABLED, QUICK_STOP_ACTIVE)
        alive = [d for d in self._drives if d.feedback is not None and not self._misses.get(d.node.id)]
        if any(self._state(d) in powered for d in alive):
            self.stop()
            self._wait_for(lambda: not any(self._state(d) in powered for d in alive), self.config.timing.enable_timeout)
        with self._lock.bounded():
            self._command = PowerCommand.DISABLE
        self._wait_for(lambda: all(self._state(d) in (SWITCH_ON_DISABLED, *FAULT_STATES) for d in alive),
                       self.config.timing.enable_timeout)
        if self.config.master.heartbeat:
            assert self._hb is not None and self._vacuum is not None
            sign_off((*self._drives, self._vacuum), self._hb, self.config.master.node_id)

    def _teardown(self) -> None:
        """Stop the control thread, send NMT pre-operational to every node, close the bus; never cut short."""
        self._stop_thread.set()
        if self._thread is not None:
            self._thread.join(timeout=2.0)
            if self._thread.is_alive():
                logger.error("the control thread did not stop within 2 s; leaving it behind")
        self._thread = None
        self._motion = False  # the control thread is gone (or hung): no lock needed, none waited for
        self._space.set()
        network, self._network = self._network, None
        if network is not None:
            close_network(network, self.config.node_ids, self._hb, self._receiver)

    def __enter__(self) -> Cobot:
        self.connect()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.disconnect()

    # ------------------------------------------------------------------ commands

    def enable(self, timeout: float | None = None) -> None:
        """Bring every drive to OPERATION ENABLED, holding the current position; then `stream` is allowed."""
        timeout = self.config.timing.enable_timeout if timeout is None else timeout
        with self._lock.bounded():
            self._require_connected()
            self._raise_fault()
            if self._motion:
                return
            q = self._positions()
            outside = [f"{n} at {x:.4f} rad (limits {lo:.3f}..{hi:.3f})" for n, x, lo, hi in
                       zip(self.joint_names, q, self.limits.q_lower, self.limits.q_upper) if not lo <= x <= hi]
            if outside:
                raise NotReadyError(f"cannot enable: joints outside their limits: {'; '.join(outside)}")
            self._command = PowerCommand.ENABLE
        self._wait_for(lambda: self._motion or self._fault is not None, timeout)
        with self._lock.bounded():
            self._raise_fault()
            if not self._motion:
                self._command = PowerCommand.DISABLE
                states = ", ".join(f"{d.label}: {self._state(d)}" for d in self._drives)
                raise DriverError(f"drives did not reach {OPERATION_ENABLED} within {timeout} s ({states})")
        logger.info("drives enabled (CSP)")

    def stream(self, q: np.ndarray, timeout: float | None = None) -> None:
        """Queue the next joint setpoint (rad, robot joint order); one setpoint is sent per control cycle.

        Refused with SetpointError (nothing queued, nothing sent) unless finite, within the joint limits
        and at most v_max * period away from the previous setpoint. Blocks while the queue is full; raises
        the latched fault if one occurs, NotReadyError if the drives are not enabled, DriverError if the
        control cycle stalls (queue still full after `timeout`) or hangs (driver lock held).
        """
        depth = self.config.timing.setpoint_queue_depth
        timeout = self.period * (depth + 25) if timeout is None else timeout
        try:
            q = setpoint_array(q)
        except (TypeError, ValueError) as exc:
            self._refused += 1
            raise SetpointError(f"setpoint is not an array of joint positions: {exc}") from exc
        end = time.monotonic() + timeout
        while True:
            with self._lock.bounded():
                self._require_streaming()
                if len(self._queue) < depth:
                    reference = self._queue[-1] if self._queue else self._hold
                    assert reference is not None
                    self._validate(q, reference)
                    self._queue.append(q)
                    return
                self._space.clear()  # under the lock: a setpoint taken from here on sets it again
            remaining = end - time.monotonic()
            if remaining <= 0:
                raise DriverError(f"setpoint queue still full after {timeout:.3f} s: the control cycle is stalled")
            self._space.wait(remaining)

    def _validate(self, q: np.ndarray, reference: np.ndarray) -> None:
        problem = setpoint_problem(q, reference, self.limits, self.period, self.joint_names)
        if problem:
            self._refused += 1
            raise SetpointError(f"setpoint refused: {problem}")

    def set_vacuum(self, on: bool, blow_off: bool = False) -> None:
        """Command the vacuum generator (sent every cycle). Works during a drive fault, so a part stays held."""
        if not isinstance(on, (bool, np.bool_)) or not isinstance(blow_off, (bool, np.bool_)):
            raise SetpointError(f"vacuum command must be booleans, got on={on!r}, blow_off={blow_off!r}")
        if on and blow_off:
            raise SetpointError("vacuum and blow-off cannot be commanded at the same time")
        with self._lock.bounded():
            self._require_connected()
            assert self._vacuum is not None
            fault = self._fault
            if isinstance(fault, BusError) or (isinstance(fault, NodeLostError)
                                               and fault.node_id == self.config.vacuum.node_id):
                raise fault
            self._vacuum.vacuum_on, self._vacuum.blow_off = bool(on), bool(blow_off)

    def stop(self) -> None:
        """Quick stop: every enabled drive decelerates on its quick-stop ramp; queued setpoints are dropped.

        Never hangs: the request is posted without the lock and carried out here or by the control thread
        at its next cycle. If the control thread holds the lock (hung), this logs an error and returns; the
        request waits for it, and devices consuming the master's heartbeat disable themselves meanwhile.
        """
        if self._network is None:
            return
        self._lock.post(None)
        if not self._lock.acquire(timeout=self._lock.timeout):
            logger.error("quick stop requested, but the control thread has held the driver lock for %.1f s: "
                         "it is hung", self._lock.timeout)
            return
        try:
            self._apply_requests()
        finally:
            self._lock.release()
        logger.info("quick stop commanded")

    def reset_faults(self, timeout: float | None = None) -> None:
        """Fault reset (controlword bit 7) on faulted drives, disable the others; clears the latched fault.

        Afterwards every drive is SWITCH ON DISABLED and `enable()` may be called again. Raises if a node is
        still silent or not OPERATIONAL (reconnect then), or a drive stays in FAULT.
        """
        timeout = self.config.timing.enable_timeout if timeout is None else timeout
        with self._lock.bounded():
            self._require_connected()
            if isinstance(self._fault, BusError):
                raise self._fault
            self._command = PowerCommand.FAULT_RESET
            self._halt()
        assert self._hb is not None
        ids = self.config.node_ids
        done = self._wait_for(lambda: all(self._state(d) == SWITCH_ON_DISABLED for d in self._drives)
                              and not self._hb.expired() and self._hb.all_in_state(OPERATIONAL, ids), timeout)
        with self._lock.bounded():
            if not done:
                self._command = PowerCommand.DISABLE
                problems = [f"{d.label}: {self._state(d)}" for d in self._drives if self._state(d) != SWITCH_ON_DISABLED]
                problems += [f"{self._label(n)}: no heartbeat for {age:.2f} s" for n, age in self._hb.expired()]
                problems += [f"{self._label(n)}: NMT {nmt_state_name(self._hb.state(n))} (reconnect)"
                             for n in ids if self._hb.state(n) != OPERATIONAL]
                raise DriverError(f"fault reset did not complete within {timeout} s: {'; '.join(problems)}")
            if self._fault is not None:
                logger.info("fault cleared: %s", self._fault)
            self._fault = None
            self._fault_at = None
            self._command = PowerCommand.DISABLE
            self._misses = dict.fromkeys(self._misses, 0)

    def check(self) -> None:
        """Raise the latched fault, if any (for runtimes that poll)."""
        with self._lock.bounded():
            self._raise_fault()

    # ------------------------------------------------------------------ state

    @property
    def setpoint(self) -> np.ndarray:
        """Last accepted joint setpoint (rad): where the next streamed setpoint must start from."""
        with self._lock.bounded():
            self._require_streaming()
            assert self._hold is not None
            return (self._queue[-1] if self._queue else self._hold).copy()

    def joint_state(self) -> JointState:
        """Latest joint positions (rad), velocities (rad/s) and drive states."""
        with self._lock.bounded():
            self._require_connected()
            fbs = [d.feedback for d in self._drives]
        if any(fb is None for fb in fbs):
            raise NotReadyError("no joint feedback yet")
        now = time.monotonic()
        return JointState(
            positions=np.array([d.conversion.to_rad(fb.position) for d, fb in zip(self._drives, fbs)]),
            velocities=np.array([d.conversion.velocity_to_rad(fb.velocity) for d, fb in zip(self._drives, fbs)]),
            drive_states=tuple(fb.state for fb in fbs),
            sync_index=min(fb.sync_index for fb in fbs),
            age=now - min(fb.received_at for fb in fbs),
        )

    def vacuum_state(self) -> VacuumState:
        """Latest vacuum level (kPa below atmosphere), part-gripped/lost flags and the command being sent."""
        with self._lock.bounded():
            self._require_connected()
            assert self._vacuum is not None
            fb, vac = self._vacuum.feedback, self._vacuum
            if fb is None:
                raise NotReadyError("no vacuum feedback yet")
            return VacuumState(fb.level_kpa, fb.part_gripped, fb.part_lost, vac.vacuum_on, vac.blow_off,
                               time.monotonic() - fb.received_at)

    def status(self) -> CobotStatus:
        """Everything a supervisor or a report wants to know, in one snapshot."""
        hb = self._hb
        ids = self.config.node_ids
        connected = self._network is not None
        return CobotStatus(
            connected=connected,
            enabled=self._motion,
            drive_states={d.name: self._state(d) for d in self._drives},
            nmt_states={n: nmt_state_name(hb.state(n) if hb else None) for n in ids},
            fault=self._fault,
            fault_at=self._fault_at,
            heartbeat_lost=tuple(n for n, _ in hb.expired()) if (hb and connected) else (),
            stats=self.stats(),
        )

    def stats(self) -> DriverStats:
        cyc = self._cycle_stats.summary()
        rx = self._receiver.stats() if self._receiver else None
        return DriverStats(
            cycles=cyc.cycles, missed_cycles=cyc.missed, lateness_p50=cyc.lateness_p50,
            lateness_p99=cyc.lateness_p99, lateness_max=cyc.lateness_max,
            frames_tx=self._frames_tx, bits_tx=self._bits_tx,
            frames_rx=rx.frames_rx if rx else 0, bits_rx=rx.bits_rx if rx else 0,
            lost_feedback=self._lost_feedback, underruns=self._underruns, refused_setpoints=self._refused,
            unknown_frames=rx.unknown_id + rx.remote_frames if rx else 0,
            bad_length_frames=rx.bad_length if rx else 0, error_frames=rx.error_frames if rx else 0,
            emcy_received=self._emcy_count,
        )

    def add_cycle_observer(self, observer: Callable[[CycleSample], None]) -> None:
        """Call `observer` from the control thread after every cycle (keep it fast). An exception in it
        latches a fault (quick stop): observers are monitors, and a monitor that fails must not fail open."""
        self._observers.append(observer)

    def remove_cycle_observer(self, observer: Callable[[CycleSample], None]) -> None:
        self._observers.remove(observer)

    # ------------------------------------------------------------------ control thread

    def _run(self, stop: threading.Event) -> None:
        if self.config.timing.realtime_priority:
            make_current_thread_realtime(self.config.timing.realtime_priority)
        timer = CycleTimer(self.period)
        timer.start()
        while not stop.is_set():
            tick = timer.wait()
            try:
                self._cycle(tick)
            except Exception as exc:  # the control thread must keep running and stop the arm
                logger.exception("control cycle %d failed", tick.index)
                self._latch(DriverError(f"control cycle {tick.index} failed: {exc!r}"))

    def _cycle(self, tick: Tick) -> None:
        assert self._receiver is not None
        with self._lock:
            self._apply_requests()
        if self._receiver.exception is not None:
            self._latch(BusError(f"CAN receive failed on {self._bus_name()}: {self._receiver.exception}"))
            return
        self._check_feedback()
        if not self._send_frame(self._send_sync):
            self._sync_sent = False
            return
        lateness = time.monotonic() - tick.deadline
        self._cycle_stats.record(lateness, tick.skipped)
        self._sync_index = tick.index
        self._sync_sent = True
        if self.config.master.heartbeat and tick.index >= self._heartbeat_due:
            self._heartbeat_due = tick.index + self._heartbeat_cycles
            self._send_frame(self._send_heartbeat)
        self._supervise()
        setpoint = self._send_commands()
        if self._observers:
            self._notify_observers(tick.index, lateness, setpoint)

    def _send_sync(self) -> int:
        assert self._network is not None
        self._network.sync.transmit()
        return 0

    def _send_heartbeat(self) -> int:
        assert self._network is not None
        self._network.send_message(0x700 + self.config.master.node_id, bytes([OPERATIONAL]))
        return 1

    def _send_frame(self, send: Callable[[], int]) -> bool:
        try:
            length = send()
        except (can.CanError, OSError) as exc:
            self._latch(BusError(f"CAN send failed on {self._bus_name()}: {exc}"))
            return False
        self._frames_tx += 1
        self._bits_tx += frame_bits(length)
        return True

    def _check_feedback(self) -> None:
        """Every device must have answered the previous SYNC with its status TPDO."""
        if not self._sync_sent:
            return
        assert self._vacuum is not None
        limit = self.config.timing.max_missed_feedback
        for dev in (*self._drives, self._vacuum):
            node_id = dev.node.id
            if dev.rx_count != self._last_rx.get(node_id):
                self._last_rx[node_id] = dev.rx_count
                self._misses[node_id] = 0
                continue
            self._lost_feedback += 1
            self._misses[node_id] = self._misses.get(node_id, 0) + 1
            if self._misses[node_id] == limit:
                self._latch(FeedbackLostError(f"{self._label(node_id)}: no TPDO for {limit} consecutive SYNC cycles",
                                              node_id, self._name(node_id)))

    def _supervise(self) -> None:
        assert self._receiver is not None and self._hb is not None
        if self._receiver.bus_off:
            self._latch(BusOffError(f"CAN controller on {self._bus_name()} is bus-off"))
        expired = dict(self._hb.expired())
        self._lost_logged &= expired.keys()
        for node_id, age in expired.items():
            if node_id not in self._lost_logged:
                self._lost_logged.add(node_id)
                self._latch(HeartbeatLostError(
                    f"heartbeat of {self._label(node_id)} lost: none for {age * 1000:.0f} ms "
                    f"(consumer time {self._hb.timeout * 1000:.0f} ms)", node_id, self._name(node_id)))
        for node_id in self.config.node_ids:
            state = self._hb.state(node_id)
            if state is not None and state != OPERATIONAL:
                self._latch(NodeLostError(f"{self._label(node_id)} left NMT OPERATIONAL: reports "
                                          f"{nmt_state_name(state)}", node_id, self._name(node_id)))
        for drive in self._drives:
            state = self._state(drive)
            if state in FAULT_STATES:
                self._latch(DeviceFaultError(f"{drive.label} is in {state}", drive.node.id, drive.name, None))
            elif self._motion and state != OPERATION_ENABLED:
                self._latch(DriverError(f"{drive.label} left {OPERATION_ENABLED}: now {state}"))

    def _send_commands(self) -> np.ndarray | None:
        assert self._vacuum is not None
        with self._lock:
            command, setpoint = self._command, None
            if self._motion:
                if self._queue:
                    setpoint = self._queue.popleft()
                    self._space.set()
                    self._moving = bool(np.any(np.abs(setpoint - self._hold) > MOVING_FRACTION * self._max_step))
                    self._hold = setpoint
                elif self._moving:
                    self._moving = False
                    self._underruns += 1
                    logger.warning("setpoint queue ran dry while moving: holding the last setpoint (%d so far)",
                                   self._underruns)
            targets = self._hold if self._motion else None
        fbs = [d.feedback for d in self._drives]
        wanted = targets if targets is not None else np.array(
            [np.nan if fb is None else d.conversion.to_rad(fb.position) for d, fb in zip(self._drives, fbs)])
        plan = plan_rpdos([None if fb is None else fb.state for fb in fbs], command,
                          [d.last_controlword for d in self._drives], wanted,
                          np.array([d.last_target for d in self._drives]), self.limits, self.joint_names)
        if plan.refused:
            drive = self._drives[plan.refused[0]]
            source = "held setpoint" if targets is not None else "measured position"
            self._latch(DeviceFaultError(f"{drive.label}: {source} refused as RPDO target: {plan.problem}",
                                         drive.node.id, drive.name, None))
        for drive, rpdo in zip(self._drives, plan.frames):
            if rpdo is not None and not self._send_frame(partial(drive.send, rpdo.controlword, rpdo.target)):
                return setpoint
        self._send_frame(self._vacuum.send)
        if command is PowerCommand.ENABLE and targets is None and not plan.refused and all(
                self._state(d) == OPERATION_ENABLED for d in self._drives):
            with self._lock:
                if self._command is PowerCommand.ENABLE and self._fault is None:
                    self._hold = wanted.copy()  # the measured positions this cycle's guard accepted
                    self._moving = False
                    self._motion = True
        return setpoint

    def _notify_observers(self, cycle: int, lateness: float, setpoint: np.ndarray | None) -> None:
        fbs = [d.feedback for d in self._drives]
        if any(fb is None for fb in fbs):
            return
        sample = CycleSample(cycle, lateness, setpoint, self._positions(), np.array([fb.sync_index for fb in fbs]))
        for observer in list(self._observers):
            try:
                observer(sample)
            except Exception as exc:  # observers are safety monitors: one that fails must not fail open
                logger.exception("cycle observer %r failed", observer)
                self._latch(DriverError(f"cycle observer {getattr(observer, '__qualname__', observer)!r} "
                                        f"failed: {exc!r}"))

    def _latch(self, error: DriverError) -> None:
        """Keep the first fault and quick-stop; control thread only (other threads post to the lock)."""
        with self._lock:
            if self._fault is None:
                self._fault = error
                self._fault_at = time.monotonic()
                self._command = PowerCommand.QUICK_STOP
                logger.error("cobot fault, quick stop: %s", error)
            self._halt()

    def _apply_requests(self) -> None:
        """Carry out the quick stops and faults other threads posted without the lock; lock held."""
        for request in self._lock.drain():
            if request is None:
                self._command = PowerCommand.QUICK_STOP
                self._halt()
            else:
                self._latch(request)

    def _halt(self) -> None:
        """Streaming ends: queued setpoints are dropped and a blocked `stream` wakes up; lock held."""
        self._motion = False
        self._queue.clear()
        self._space.set()

    def _on_emcy(self, node_id: int, emcy: EmcyError) -> None:
        self._emcy_count += 1
        if emcy.code & 0xFF00 == 0:
            logger.info("%s: EMCY error reset", self._label(node_id))
            return
        text = f"{self._label(node_id)}: EMCY 0x{emcy.code:04X} ({emcy.get_desc()}), error register 0x{emcy.register:02X}"
        if emcy.register:  # latched by the control thread at its next cycle (this is the receive thread)
            self._lock.post(DeviceFaultError(text, node_id, self._name(node_id), emcy.code))
        else:
            logger.warning("%s (no active error)", text)

    # ------------------------------------------------------------------ helpers

    def _current_sync(self) -> int:
        return self._sync_index

    def _positions(self) -> np.ndarray:
        return np.array([d.position_rad() for d in self._drives])

    @staticmethod
    def _state(drive: Cia402Drive) -> str:
        fb = drive.feedback
        return fb.state if fb is not None else "NO FEEDBACK"

    def _name(self, node_id: int) -> str:
        for drive in self._drives:
            if drive.node.id == node_id:
                return drive.name
        return "vacuum generator"

    def _label(self, node_id: int) -> str:
        return f"node {node_id} ({self._name(node_id)})"

    def _bus_name(self) -> str:
        bus = self.config.bus
        return f"{bus.interface}:{bus.channel}"

    def _wait_for(self, predicate: Callable[[], bool], timeout: float) -> bool:
        end = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > end:
                return False
            time.sleep(self.period / 2)
        return True

    def _require_connected(self) -> None:
        if self._network is None:
            raise NotReadyError("cobot is not connected: call connect()")

    def _require_streaming(self) -> None:
        self._require_connected()
        self._raise_fault()
        if not self._motion:
            raise NotReadyError("drives are not enabled: call enable() before streaming setpoints")

    def _raise_fault(self) -> None:
        if self._fault is not None:
            raise self._fault
