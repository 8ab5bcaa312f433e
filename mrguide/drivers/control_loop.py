"""The `Cobot`'s control thread: the SYNC cycle on absolute monotonic deadlines.

Each cycle: carry out posted requests, check the receive thread and the feedback, send SYNC, the master's
heartbeat when due (every device consumes it, 0x1016, so a hung thread or a dead PC disables the drives
without the master's help), supervise, then one RPDO per drive (controlword + target position) and one to
the vacuum generator, which the devices apply at the next SYNC; finally the cycle observers. Every RPDO's
target is checked once more right before it is sent (`setpoint_guard.plan_rpdos`).
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable
from functools import partial

import can
import numpy as np

from mrguide.drivers import supervision
from mrguide.drivers.bus import frame_bits
from mrguide.drivers.cia402 import OPERATION_ENABLED, PowerCommand
from mrguide.drivers.cobot_core import CobotCore
from mrguide.drivers.cobot_state import CycleSample
from mrguide.drivers.cycle import CycleTimer, Tick
from mrguide.drivers.errors import BusError, DeviceFaultError, DriverError
from mrguide.drivers.heartbeat import OPERATIONAL
from mrguide.drivers.realtime import hold_switch_interval, make_current_thread_realtime, release_switch_interval
from mrguide.drivers.setpoint_guard import plan_rpdos
from mrguide.drivers.thread_clock import Gap, ThreadClock

logger = logging.getLogger(__name__)

#: A setpoint step above this fraction of v_max * period means the arm is moving (for underrun counting).
MOVING_FRACTION = 0.01
#: How long `stop` waits for the control thread to end (s) before leaving it behind.
JOIN_TIMEOUT = 2.0


class ControlLoop:
    """Runs `cycle` once per control period in a thread of its own, from `start` until `stop`."""

    def __init__(self, core: CobotCore) -> None:
        self.core = core
        self.thread: threading.Thread | None = None
        self._stop = threading.Event()
        self._switch_interval = 0.0  # held from `start` to `stop` (timing.switch_interval)

    @property
    def alive(self) -> bool:
        return self.thread is not None and self.thread.is_alive()

    def start(self) -> None:
        self._switch_interval = self.core.config.timing.switch_interval
        if self._switch_interval:
            hold_switch_interval(self._switch_interval)
        self._stop = threading.Event()  # one per thread: a thread left behind never resumes
        self.thread = threading.Thread(target=self._run, args=(self._stop,), name="mrguide-can-cycle", daemon=True)
        self.thread.start()

    def stop(self) -> None:
        """End the thread (waits up to JOIN_TIMEOUT; a hung thread is logged and left behind)."""
        self._stop.set()
        if self.thread is not None:
            self.thread.join(timeout=JOIN_TIMEOUT)
            if self.thread.is_alive():
                logger.error("the control thread did not stop within %g s; leaving it behind", JOIN_TIMEOUT)
        self.thread = None
        if self._switch_interval:
            release_switch_interval(self._switch_interval)
            self._switch_interval = 0.0

    def _run(self, stop: threading.Event) -> None:
        priority = self.core.config.timing.realtime_priority
        if priority:
            make_current_thread_realtime(priority)
        timer = CycleTimer(self.core.period)
        clock = ThreadClock()  # this thread's: where the time went when deadlines are skipped
        timer.start()
        previous = clock.read()
        try:
            while not stop.is_set():
                tick = timer.wait()
                started = clock.read()
                if tick.skipped:
                    self.core.cycle_stats.record_miss(Gap.between(previous, started, tick.slept), tick.skipped)
                previous = started
                try:
                    self.cycle(tick)
                except Exception as exc:  # the control thread must keep running and stop the arm
                    logger.exception("control cycle %d failed", tick.index)
                    supervision.latch(self.core, DriverError(f"control cycle {tick.index} failed: {exc!r}"))
                self.core.cycle_stats.record_work(time.monotonic() - started.wall)
        finally:
            clock.close()

    def cycle(self, tick: Tick) -> None:
        """One control period (see the module docstring)."""
        core = self.core
        assert core.receiver is not None
        with core.lock:
            supervision.apply_requests(core)
        if core.receiver.exception is not None:
            supervision.latch(core, BusError(f"CAN receive failed on {core.bus_name()}: {core.receiver.exception}"))
            return
        supervision.check_feedback(core)
        sync_wall = time.time()
        if not self._send_frame(self._send_sync):
            core.sync_sent = False
            return
        core.sync_wall = sync_wall
        lateness = time.monotonic() - tick.deadline
        core.cycle_stats.record(lateness, tick.skipped)
        core.sync_index = tick.index
        core.sync_sent = True
        if core.config.master.heartbeat and tick.index >= core.heartbeat_due:
            core.heartbeat_due = tick.index + core.heartbeat_cycles
            self._send_frame(self._send_heartbeat)
        supervision.supervise(core)
        setpoint = self._send_commands()
        if core.observers:
            self._notify_observers(tick.index, lateness, setpoint)

    # ------------------------------------------------------------------ frames

    def _send_sync(self) -> int:
        assert self.core.network is not None
        self.core.network.sync.transmit()
        return 0

    def _send_heartbeat(self) -> int:
        assert self.core.network is not None
        self.core.network.send_message(0x700 + self.core.config.master.node_id, bytes([OPERATIONAL]))
        return 1

    def _send_frame(self, send: Callable[[], int]) -> bool:
        """Send one frame (`send` returns its data length); a send error is latched as a bus fault."""
        try:
            length = send()
        except (can.CanError, OSError) as exc:
            supervision.latch(self.core, BusError(f"CAN send failed on {self.core.bus_name()}: {exc}"))
            return False
        self.core.frames_tx += 1
        self.core.bits_tx += frame_bits(length)
        return True

    # ------------------------------------------------------------------ commands

    def _next_target(self) -> tuple[PowerCommand, np.ndarray | None, np.ndarray | None]:
        """The power command, the setpoint taken from the queue (if any) and the target to hold (None: not
        streaming); takes the lock."""
        core = self.core
        with core.lock:
            command, setpoint = core.command, None
            if core.motion:
                if core.queue:
                    setpoint = core.queue.popleft()
                    core.space.set()
                    core.moving = bool(np.any(np.abs(setpoint - core.hold) > MOVING_FRACTION * core.max_step))
                    core.hold = setpoint
                elif core.moving:  # counted here, logged by `Cobot.stream` (no I/O in the control thread)
                    core.moving = False
                    core.underruns += 1
            return command, setpoint, core.hold if core.motion else None

    def _send_commands(self) -> np.ndarray | None:
        """One RPDO per drive and one to the vacuum generator; returns the setpoint taken from the queue."""
        core = self.core
        assert core.vacuum is not None
        command, setpoint, targets = self._next_target()
        fbs = [d.feedback for d in core.drives]
        wanted = (
            targets
            if targets is not None
            else np.array(
                [np.nan if fb is None else d.conversion.to_rad(fb.position) for d, fb in zip(core.drives, fbs)]
            )
        )
        plan = plan_rpdos(
            [None if fb is None else fb.state for fb in fbs],
            command,
            [d.last_controlword for d in core.drives],
            wanted,
            np.array([d.last_target for d in core.drives]),
            core.limits,
            core.joint_names,
        )
        if plan.refused:
            drive = core.drives[plan.refused[0]]
            source = "held setpoint" if targets is not None else "measured position"
            supervision.latch(
                core,
                DeviceFaultError(
                    f"{drive.label}: {source} refused as RPDO target: {plan.problem}", drive.node_id, drive.name, None
                ),
            )
        for drive, rpdo in zip(core.drives, plan.frames):
            if rpdo is not None and not self._send_frame(partial(drive.send, rpdo.controlword, rpdo.target)):
                return setpoint
        self._send_frame(core.vacuum.send)
        if (
            command is PowerCommand.ENABLE
            and targets is None
            and not plan.refused
            and all(core.state(d) == OPERATION_ENABLED for d in core.drives)
        ):
            with core.lock:
                if core.command is PowerCommand.ENABLE and core.fault is None:
                    core.hold = wanted.copy()  # the measured positions this cycle's guard accepted
                    core.moving = False
                    core.motion = True
        return setpoint

    def _notify_observers(self, cycle: int, lateness: float, setpoint: np.ndarray | None) -> None:
        core = self.core
        latest = [d.feedback for d in core.drives]
        fbs = [fb for fb in latest if fb is not None]
        if len(fbs) < len(latest):
            return
        sample = CycleSample(cycle, lateness, setpoint, core.positions(), np.array([fb.sync_index for fb in fbs]))
        for observer in list(core.observers):
            try:
                observer(sample)
            except Exception as exc:  # observers are safety monitors: one that fails must not fail open
                logger.exception("cycle observer %r failed", observer)
                supervision.latch(
                    core, DriverError(f"cycle observer {getattr(observer, '__qualname__', observer)!r} failed: {exc!r}")
                )
