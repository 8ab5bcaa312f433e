"""The CAN bus: opening it from config, and a receive thread that checks every frame before canopen does.

`BusReceiver` replaces canopen's python-can Notifier. Frames with unexpected CAN IDs or lengths, remote
frames and error frames never reach canopen's callbacks (which would raise on a short frame); they are
counted and logged instead, so garbage on the bus cannot crash or confuse the driver.

It also keeps the bus's own clock (`horizon`): every frame carries its receive timestamp, taken by the interface
(the kernel, the adapter, or python-can's virtual bus) when it arrived, not when this thread got round to it. A
receiver that fell behind — its process stalled by the OS, the garbage collector or another thread holding the
GIL — still has the frames that arrived meanwhile in its queue; judged on the horizon, a heartbeat waiting there is
not a lost one, as a device's CAN controller stamps a frame on arrival, not when its firmware reads it.
"""

from __future__ import annotations

import logging
import queue
import select
import threading
import time
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

import can
import canopen

from mrguide.drivers.config import BusConfig
from mrguide.drivers.errors import BusError
from mrguide.drivers.realtime import make_current_thread_realtime

logger = logging.getLogger(__name__)

#: SocketCAN error-frame class bit for bus-off (linux/can/error.h CAN_ERR_BUSOFF).
CAN_ERR_BUSOFF = 0x40
#: Log the first few rejected frames at WARNING, then only every this many.
_LOG_EVERY = 1000
#: s: a receive timestamp this far from the wall clock is on another epoch (an adapter's own counter): the receiver
#: then stamps frames itself when it dispatches them.
FOREIGN_EPOCH_S = 3600.0


def frame_bits(dlc: int, extended: bool = False) -> int:
    """Worst-case length of a classic CAN data frame in bits, stuff bits and 3-bit interframe space included.

    Uses the bound of Davis et al. (2007), "CAN schedulability analysis: refuted, revisited and revised":
    g + 8*dlc + 13 + floor((g + 8*dlc - 1) / 4) with g = 34 (11-bit ID) or 54 (29-bit ID).
    """
    g = 54 if extended else 34
    return g + 8 * dlc + 13 + (g + 8 * dlc - 1) // 4


def open_bus(config: BusConfig) -> can.BusABC:
    """Open the python-can bus described by `config`; failures raise BusError with interface and channel."""
    where = f"{config.interface} channel {config.channel!r} at {config.bitrate} bit/s"
    try:
        # keyword arguments of the interface's bus class (bus_options.py), none of can.Bus's own parameters
        options: dict[str, Any] = dict(config.options)
        return can.Bus(interface=config.interface, channel=config.channel, bitrate=config.bitrate, **options)
    except can.CanInterfaceNotImplementedError as exc:
        raise BusError(f"CAN interface {config.interface!r} is not usable here: {exc}") from exc
    except (can.CanError, OSError, ValueError, TypeError) as exc:
        raise BusError(f"cannot open CAN bus {where}: {exc}") from exc


def stop_periodic_tasks(bus: can.BusABC, timeout: float = 1.0) -> None:
    """Stop `bus`'s periodic tasks and wait for each one's thread to leave its loop, so that none sends on a bus shut down
    under it: python-can's `stop` only flags a task, and one caught mid-send would raise in its thread (a traceback
    on stderr at the end of a run, e.g. a heartbeat producer writing to a closed pipe)."""
    tasks = list(getattr(bus, "_periodic_tasks", ()))
    bus.stop_all_periodic_tasks()
    for task in tasks:
        thread = getattr(task, "thread", None)
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)


def frames_pending(bus: can.BusABC) -> bool | None:
    """Whether frames wait in `bus`'s receive queue now; None if the interface cannot tell. A bus may answer itself
    (a `frames_pending()` method, as the simulator's fault-injecting wrapper does); python-can's virtual bus holds a
    queue; a selectable interface (SocketCAN, UDP multicast) is polled without waiting."""
    own = getattr(bus, "frames_pending", None)
    if callable(own):
        return own()
    waiting = getattr(bus, "queue", None)
    if isinstance(waiting, queue.Queue):
        return not waiting.empty()
    try:
        readable, _, _ = select.select([bus.fileno()], [], [], 0)
    except (NotImplementedError, OSError, ValueError):
        return None
    return bool(readable)


@dataclass(frozen=True)
class ReceiverStats:
    """What a receiver has seen since it was created."""

    frames_rx: int
    bits_rx: int
    unknown_id: int
    bad_length: int
    remote_frames: int
    error_frames: int
    handler_errors: int
    bus_off: bool


class BusReceiver:
    """Receive thread of one bus: forwards frames with an expected CAN ID and length to a canopen Network.

    Replaces canopen's python-can Notifier (so the network must not be `connect()`ed): a receive failure
    stops the thread and is kept in `exception` for the owner to report; the thread can run with
    real-time priority.
    """

    #: Longest wait in one recv() call, bounding how long stop() takes.
    POLL = 0.05

    def __init__(self, network: canopen.Network, label: str, realtime_priority: int = 0) -> None:
        if network.bus is None:
            raise ValueError("the canopen Network needs its bus before a receiver is created")
        self._network = network
        self._bus: can.BusABC = network.bus
        self.label = label
        self._priority = realtime_priority
        self._expected: dict[int, frozenset[int] | None] = {}
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        #: The exception that stopped reception, if any.
        self.exception: BaseException | None = None
        self._frames_rx = self._bits_rx = 0
        self._unknown_id = self._bad_length = self._remote = self._error_frames = self._handler_errors = 0
        self._bus_off = False
        self._horizon = time.time()
        self._own_stamps = False  # the interface's timestamps are on another epoch: stamp at dispatch
        self._waiting = False  # the thread waits in recv()

    def horizon(self) -> float:
        """The bus time (s, the epoch of the frames' receive timestamps) up to which every frame has been dispatched:
        now while the thread waits on an empty queue, else the latest dispatched frame's timestamp (or when reception
        last found the bus idle, for an interface that cannot tell whether frames wait)."""
        if self._waiting and frames_pending(self._bus) is False:
            self._horizon = max(self._horizon, time.time())  # never back: a later look sees at least this
        return self._horizon

    def expect(self, can_id: int, lengths: Iterable[int] | None) -> None:
        """Accept frames on `can_id` whose data length is in `lengths` (None: any length)."""
        self._expected[can_id] = None if lengths is None else frozenset(lengths)

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name=f"mrguide-can-rx-{self.label}", daemon=True)
        self._thread.start()

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=1.0)
        self._thread = None

    def _run(self) -> None:
        if self._priority:
            make_current_thread_realtime(self._priority)
        while not self._stop.is_set():
            try:
                self._waiting = True
                msg = self._bus.recv(self.POLL)
                self._waiting = False
            except Exception as exc:  # whatever the interface raises ends reception; the owner reports it
                self.exception = exc
                logger.error("%s: CAN receive failed, reception stopped: %s", self.label, exc)
                return
            if msg is not None:
                self.dispatch(msg)
            else:  # nothing arrived for POLL: every frame up to now has been dispatched
                self._horizon = max(self._horizon, time.time())

    def dispatch(self, msg: can.Message) -> None:
        """Check one frame and hand it to canopen (with its receive timestamp) if it is expected."""
        stamp = self._stamp(msg)
        self._horizon = max(self._horizon, stamp)
        self._frames_rx += 1
        self._bits_rx += frame_bits(len(msg.data), msg.is_extended_id)
        if msg.is_error_frame:
            self._error_frames += 1
            if msg.arbitration_id & CAN_ERR_BUSOFF and not self._bus_off:
                self._bus_off = True
                logger.error("%s: CAN controller reports bus-off (error frame 0x%X)", self.label, msg.arbitration_id)
            return
        if msg.is_remote_frame:
            self._remote += 1
            self._reject("remote frame", msg, self._remote)
            return
        if msg.is_extended_id or msg.arbitration_id not in self._expected:
            self._unknown_id += 1
            self._reject("unexpected CAN ID", msg, self._unknown_id)
            return
        lengths = self._expected[msg.arbitration_id]
        if lengths is not None and len(msg.data) not in lengths:
            self._bad_length += 1
            self._reject(f"wrong length (expected {sorted(lengths)})", msg, self._bad_length)
            return
        try:
            self._network.notify(msg.arbitration_id, msg.data, stamp)
        except Exception:  # a callback bug must not stop reception of the next frame
            self._handler_errors += 1
            logger.exception("%s: handler for CAN ID 0x%03X failed", self.label, msg.arbitration_id)

    def _stamp(self, msg: can.Message) -> float:
        """The frame's receive time on the wall clock's epoch: the interface's timestamp, or now if it has none."""
        now = time.time()
        if not self._own_stamps and abs(msg.timestamp - now) > FOREIGN_EPOCH_S:
            self._own_stamps = True
            logger.warning(
                "%s: the interface's receive timestamps are not on the wall clock: stamping frames on dispatch",
                self.label,
            )
        return now if self._own_stamps else msg.timestamp

    def _reject(self, why: str, msg: can.Message, count: int) -> None:
        level = logging.WARNING if count <= 10 or count % _LOG_EVERY == 0 else logging.DEBUG
        logger.log(
            level,
            "%s: ignored frame 0x%X [%d] %s: %s (%d so far)",
            self.label,
            msg.arbitration_id,
            len(msg.data),
            bytes(msg.data).hex(" "),
            why,
            count,
        )

    def stats(self) -> ReceiverStats:
        return ReceiverStats(
            self._frames_rx,
            self._bits_rx,
            self._unknown_id,
            self._bad_length,
            self._remote,
            self._error_frames,
            self._handler_errors,
            self._bus_off,
        )

    @property
    def bus_off(self) -> bool:
        return self._bus_off
