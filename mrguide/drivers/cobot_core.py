"""What the parts of the `Cobot` share: configuration, devices, the setpoint queue, the latched fault, counters.

The facade (`cobot.py`), the boot sequence (`boot.py`), the control thread (`control_loop.py`) and the
supervision (`supervision.py`) all work on one `CobotCore`. Fields that both the control thread and the
application touch (`command`, `motion`, `hold`, `moving`, `fault`, `queue`) are guarded by `lock`; the
control thread alone writes the cycle counters and feedback bookkeeping.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable

import canopen
import numpy as np

from mrguide.drivers.bus import BusReceiver
from mrguide.drivers.cia402 import Cia402Drive, PowerCommand
from mrguide.drivers.cobot_state import CycleSample
from mrguide.drivers.config import CobotBusConfig, resolve_limits
from mrguide.drivers.cycle import CycleStats
from mrguide.drivers.driver_lock import DriverLock
from mrguide.drivers.errors import DriverError, NotReadyError
from mrguide.drivers.heartbeat import HeartbeatConsumer
from mrguide.drivers.vacuum import VacuumGenerator
from mrguide.robot import RobotSpec


class CobotCore:
    """Shared state of one cobot on one CAN bus, and the small helpers every part needs."""

    def __init__(self, config: CobotBusConfig, robot: RobotSpec) -> None:
        self.config = config
        self.robot = robot
        self.limits = resolve_limits(config, robot)
        self.joint_names = robot.joint_names
        self.period = config.timing.control_period
        self.max_step = self.limits.v_max * self.period
        # rounded down: the master's heartbeat never comes later than the period the devices expect
        self.heartbeat_cycles = max(1, int(config.timing.heartbeat_period / self.period + 1e-9))
        self.lock = DriverLock()
        #: Set whenever the setpoint queue gets room or streaming ends (wakes a blocked `stream`).
        self.space = threading.Event()
        self.queue: deque[np.ndarray] = deque()
        self.network: canopen.Network | None = None
        self.receiver: BusReceiver | None = None
        self.hb: HeartbeatConsumer | None = None
        self.drives: list[Cia402Drive] = []
        self.vacuum: VacuumGenerator | None = None
        self.observers: list[Callable[[CycleSample], None]] = []
        self.reset_run_state()

    def reset_run_state(self) -> None:
        """Forget everything of an earlier connection (commands, fault, counters, queued setpoints)."""
        self.command = PowerCommand.DISABLE
        self.motion = False  # every drive OPERATION ENABLED and streaming allowed
        self.hold: np.ndarray | None = None  # the setpoint sent every cycle while the queue is empty
        self.moving = False
        self.fault: DriverError | None = None
        self.fault_at: float | None = None
        self.sync_index = 0
        self.sync_sent = False
        self.sync_wall = 0.0  # wall-clock time the last SYNC was sent (the epoch of the frames' receive timestamps)
        self.heartbeat_due = 1
        self.last_rx: dict[int, int] = {}
        self.misses: dict[int, int] = {}
        self.lost_logged: set[int] = set()
        self.cycle_stats = CycleStats(period=self.period)
        self.frames_tx = self.bits_tx = 0
        self.lost_feedback = self.underruns = self.refused = self.emcy_count = 0
        self.queue.clear()
        self.lock.discard_requests()

    # ------------------------------------------------------------------ helpers

    def current_sync(self) -> int:
        return self.sync_index

    def positions(self) -> np.ndarray:
        return np.array([d.position_rad() for d in self.drives])

    @staticmethod
    def state(drive: Cia402Drive) -> str:
        fb = drive.feedback
        return fb.state if fb is not None else "NO FEEDBACK"

    def name(self, node_id: int) -> str:
        for drive in self.drives:
            if drive.node_id == node_id:
                return drive.name
        return "vacuum generator"

    def label(self, node_id: int) -> str:
        return f"node {node_id} ({self.name(node_id)})"

    def bus_name(self) -> str:
        bus = self.config.bus
        return f"{bus.interface}:{bus.channel}"

    def wait_for(self, predicate: Callable[[], bool], timeout: float) -> bool:
        end = time.monotonic() + timeout
        while not predicate():
            if time.monotonic() > end:
                return False
            time.sleep(self.period / 2)
        return True

    def require_connected(self) -> None:
        if self.network is None:
            raise NotReadyError("cobot is not connected: call connect()")

    def require_streaming(self) -> None:
        self.require_connected()
        self.raise_fault()
        if not self.motion:
            raise NotReadyError("drives are not enabled: call enable() before streaming setpoints")

    def raise_fault(self) -> None:
        if self.fault is not None:
            raise self.fault
