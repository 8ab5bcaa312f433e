"""Fault injection for the simulated devices: frame loss, added delay, silent nodes, wrong position feedback.

`FaultyBus` wraps the simulator's python-can bus, so every frame the simulated devices send or receive
(PDOs, SDOs, heartbeats from python-can's cyclic tasks, EMCY) passes through the same faults. A wrong
position feedback (a slipped encoder, a wrong offset) is read by the simulated drives from here. Drive
faults and vacuum leaks are injected on the simulated cobot itself.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import random
import threading
import time
from dataclasses import dataclass

import can

from mrguide.drivers.bus import frames_pending, stop_periodic_tasks

logger = logging.getLogger(__name__)

HEARTBEAT_BASE = 0x700
SYNC = 0x080
#: COB-IDs of the four predefined TPDO/RPDO pairs.
PDO_IDS = range(0x180, 0x580)


@dataclass(frozen=True)
class FaultStats:
    dropped_rx: int
    dropped_tx: int
    silenced_tx: int
    delayed_tx: int
    #: The most a delayed frame went out after its due time (s): its delay line's thread waiting for the CPU.
    delay_overrun_s: float = 0.0


class FaultInjector:
    """Fault settings, changeable at run time from any thread."""

    def __init__(self, seed: int = 0) -> None:
        self._rng = random.Random(seed)
        self._lock = threading.Lock()
        self._drop_rate = 0.0
        self._cyclic_only = False
        self._delay = 0.0
        self._silent: dict[int, bool] = {}  # node ID -> heartbeat only
        self._position_error: dict[int, float] = {}  # node ID -> rad added to the reported position
        self._counts = dict.fromkeys(("dropped_rx", "dropped_tx", "silenced_tx", "delayed_tx"), 0)
        self._delay_overrun_s = 0.0

    def set_drop_rate(self, rate: float, cyclic_only: bool = False) -> None:
        """Drop each frame (either direction) with probability `rate`; only SYNC and PDOs if `cyclic_only`."""
        if not 0.0 <= rate < 1.0:
            raise ValueError(f"drop rate must lie in [0, 1), got {rate}")
        self._drop_rate = rate
        self._cyclic_only = cyclic_only
        logger.info("fault injection: drop rate %.3f of %s frames", rate, "SYNC/PDO" if cyclic_only else "all")

    def set_delay(self, seconds: float) -> None:
        """Delay every frame the simulated devices send by `seconds`."""
        if not 0.0 <= seconds <= 1.0:
            raise ValueError(f"delay must lie in [0, 1] s, got {seconds}")
        self._delay = seconds
        logger.info("fault injection: tx delay %.4f s", seconds)

    def silence(self, node_id: int, heartbeat_only: bool = False) -> None:
        """Node `node_id` stops sending: everything, or only its heartbeat."""
        self._silent[node_id] = heartbeat_only
        logger.info(
            "fault injection: node %d silent (%s)", node_id, "heartbeat only" if heartbeat_only else "all frames"
        )

    def unsilence(self, node_id: int) -> None:
        self._silent.pop(node_id, None)

    def is_silent(self, node_id: int) -> bool:
        """True if the node is completely silent (dead)."""
        return self._silent.get(node_id) is False

    def set_position_error(self, node_id: int, offset: float) -> None:
        """Drive `node_id` reports its position actual value (0x6064) off by `offset` rad; 0 clears it.

        Only the reported value is wrong: the drive's own loop and following-error check see the true joint."""
        self._position_error[node_id] = offset
        logger.info("fault injection: node %d reports its position %+.4f rad off", node_id, offset)

    def position_error(self, node_id: int) -> float:
        """Offset (rad) drive `node_id` adds to the position it reports."""
        return self._position_error.get(node_id, 0.0)

    @property
    def delay(self) -> float:
        return self._delay

    def blocks(self, can_id: int) -> bool:
        """Whether a frame sent by a device with this COB-ID is suppressed by a silent node."""
        heartbeat_only = self._silent.get(can_id & 0x7F)
        if heartbeat_only is None:
            return False
        return not heartbeat_only or can_id & 0x780 == HEARTBEAT_BASE

    def drop(self, can_id: int) -> bool:
        """Whether to lose this frame (random, at the configured rate)."""
        if self._drop_rate == 0.0 or (self._cyclic_only and can_id != SYNC and can_id not in PDO_IDS):
            return False
        with self._lock:
            return self._rng.random() < self._drop_rate

    def count(self, what: str) -> None:
        with self._lock:
            self._counts[what] += 1

    def overran(self, seconds: float) -> None:
        """A delayed frame went out `seconds` after its due time."""
        with self._lock:
            self._delay_overrun_s = max(self._delay_overrun_s, seconds)

    def stats(self) -> FaultStats:
        with self._lock:
            return FaultStats(**self._counts, delay_overrun_s=self._delay_overrun_s)


class _DelayLine:
    """Sends frames at their due time from one background thread; how late it was, to `faults`."""

    def __init__(self, send: can.BusABC, faults: FaultInjector) -> None:
        self._bus = send
        self._faults = faults
        self._heap: list[tuple[float, int, can.Message]] = []
        self._seq = itertools.count()
        self._cv = threading.Condition()
        self._stopped = False
        self._thread = threading.Thread(target=self._run, name="mrguide-sim-delay", daemon=True)
        self._thread.start()

    def put(self, msg: can.Message, due: float) -> None:
        with self._cv:
            heapq.heappush(self._heap, (due, next(self._seq), msg))
            self._cv.notify()

    def _run(self) -> None:
        while True:
            with self._cv:
                while not self._stopped and (not self._heap or self._heap[0][0] > time.monotonic()):
                    self._cv.wait(self._heap[0][0] - time.monotonic() if self._heap else None)
                if self._stopped:
                    return
                due, _, msg = heapq.heappop(self._heap)
            self._faults.overran(time.monotonic() - due)
            try:
                self._bus.send(msg)
            except can.CanError as exc:
                logger.warning("delayed frame 0x%X not sent: %s", msg.arbitration_id, exc)

    def stop(self) -> None:
        with self._cv:
            self._stopped = True
            self._cv.notify()
        self._thread.join(timeout=1.0)


class FaultyBus(can.BusABC):
    """A python-can bus that applies a FaultInjector to the frames of the bus it wraps."""

    def __init__(self, inner: can.BusABC, faults: FaultInjector) -> None:
        self._inner = inner
        self.faults = faults
        self._delay_line: _DelayLine | None = None
        self.channel_info = f"{inner.channel_info} with fault injection"
        super().__init__(channel=inner.channel_info)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        faults = self.faults
        if faults.blocks(msg.arbitration_id):
            faults.count("silenced_tx")
            return
        if faults.drop(msg.arbitration_id):
            faults.count("dropped_tx")
            return
        if faults.delay > 0.0:
            if self._delay_line is None:
                self._delay_line = _DelayLine(self._inner, faults)
            faults.count("delayed_tx")
            self._delay_line.put(msg, time.monotonic() + faults.delay)
            return
        self._inner.send(msg, timeout)

    def frames_pending(self) -> bool | None:
        """Whether frames wait in the wrapped bus's receive queue (for `BusReceiver.horizon`)."""
        return frames_pending(self._inner)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        msg = self._inner.recv(timeout)
        if msg is not None and not msg.is_error_frame and self.faults.drop(msg.arbitration_id):
            self.faults.count("dropped_rx")
            return None, False
        return msg, False

    def shutdown(self) -> None:
        stop_periodic_tasks(self)  # before the wrapped bus closes under a task mid-send
        super().shutdown()
        if self._delay_line is not None:
            self._delay_line.stop()
        self._inner.shutdown()
