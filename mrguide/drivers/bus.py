"""The CAN bus: opening it from config, and a receive thread that checks every frame before canopen does.

`BusReceiver` replaces canopen's python-can Notifier. Frames with unexpected CAN IDs or lengths, remote
frames and error frames never reach canopen's callbacks (which would raise on a short frame); they are
counted and logged instead, so garbage on the bus cannot crash or confuse the driver.
"""

from __future__ import annotations

import logging
import threading
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
                msg = self._bus.recv(self.POLL)
            except Exception as exc:  # whatever the interface raises ends reception; the owner reports it
                self.exception = exc
                logger.error("%s: CAN receive failed, reception stopped: %s", self.label, exc)
                return
            if msg is not None:
                self.dispatch(msg)

    def dispatch(self, msg: can.Message) -> None:
        """Check one frame and hand it to canopen if it is expected."""
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
            self._network.notify(msg.arbitration_id, msg.data, msg.timestamp)
        except Exception:  # a callback bug must not stop reception of the next frame
            self._handler_errors += 1
            logger.exception("%s: handler for CAN ID 0x%03X failed", self.label, msg.arbitration_id)

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
