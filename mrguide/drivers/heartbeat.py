"""Heartbeat consumer with a timeout, boot-up detection, and the devices' view of the master's heartbeat.

canopen's `NmtMaster` records each node's last heartbeat state but never times out. This consumer
subscribes to the same heartbeat frames and judges them on the bus's own clock: a heartbeat counts from its
receive timestamp, and "now" is the receiver's horizon (`BusReceiver.horizon`). A receive thread that fell behind
its queue — its process stalled for a moment — thus finds the heartbeats that arrived meanwhile before it judges,
and reports no node lost that was not; a node that really fell silent is still reported one consumer time after
its last heartbeat, and a bus on which nothing arrives at all advances the horizon by the receiver's idle polls.

The other direction: the master produces a heartbeat too, and every device consumes it through its
object 0x1016 (CiA 301), so a device notices a dead or hung master by itself.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from functools import partial

import canopen
from canopen.nmt import NMT_STATES

#: NMT state reported in a boot-up message.
BOOTUP = 0
#: NMT state OPERATIONAL as carried in heartbeats.
OPERATIONAL = 5
#: Consumer heartbeat time object (CiA 301); sub-index 1 holds the entry for the master.
#: EMCY error code of a heartbeat consumer time-out (CiA 301: life guard or heartbeat error).
HEARTBEAT_ERROR = 0x8130


def consumer_heartbeat_entry(producer_id: int, time_ms: int) -> int:
    """A 0x1016 entry (CiA 301): producer node ID in bits 16-23, consumer time in ms in bits 0-15; 0 = off."""
    if not 1 <= producer_id <= 127 or not 0 <= time_ms <= 0xFFFF:
        raise ValueError(f"consumer heartbeat entry: node ID {producer_id} or time {time_ms} ms out of range")
    return producer_id << 16 | time_ms if time_ms else 0


def parse_consumer_heartbeat_entry(entry: int) -> tuple[int, float] | None:
    """(producer node ID, consumer time in s) of a 0x1016 entry, or None if the entry is switched off."""
    producer_id, time_ms = entry >> 16 & 0xFF, entry & 0xFFFF
    if not 1 <= producer_id <= 127 or time_ms == 0:
        return None
    return producer_id, time_ms / 1000.0


def nmt_state_name(state: int | None) -> str:
    if state is None:
        return "NO HEARTBEAT"
    return "BOOT-UP" if state == BOOTUP else NMT_STATES.get(state, f"UNKNOWN ({state})")


#: Heartbeat data: the NMT state in bits 0-6 (bit 7 is the toggle bit of node guarding).
STATE_MASK = 0x7F


class HeartbeatConsumer:
    """Tracks heartbeat age and NMT state per node; supervision starts when `arm()` is called. `clock` gives the bus
    time the frames' timestamps are on (the receiver's horizon)."""

    def __init__(self, timeout: float, clock: Callable[[], float]) -> None:
        self.timeout = timeout
        self._clock = clock
        self._last: dict[int, float] = {}
        self._state: dict[int, int | None] = {}
        self._bootups: dict[int, threading.Event] = {}
        self._armed = False

    def watch(self, network: canopen.Network, node_id: int) -> None:
        """Start following the heartbeats of node `node_id` on `network`."""
        self._state[node_id] = None
        self._bootups[node_id] = threading.Event()
        network.subscribe(0x700 + node_id, partial(self.on_heartbeat, node_id))

    def on_heartbeat(self, node_id: int, can_id: int, data: bytes, timestamp: float) -> None:
        """A heartbeat frame of `node_id` received at `timestamp` (bus time)."""
        state = data[0] & STATE_MASK
        self._last[node_id] = max(self._last.get(node_id, timestamp), timestamp)
        self._state[node_id] = state
        if state == BOOTUP:
            self._bootups[node_id].set()

    def expect_bootup(self) -> None:
        """Forget earlier boot-up messages (call right before sending NMT reset)."""
        for event in self._bootups.values():
            event.clear()

    def wait_bootup(self, timeout: float) -> list[int]:
        """Wait for a boot-up message from every watched node; returns the node IDs that sent none."""
        end = self._clock() + timeout
        for event in self._bootups.values():
            event.wait(max(0.0, end - self._clock()))
        return [n for n, event in self._bootups.items() if not event.is_set()]

    def arm(self) -> None:
        """Start supervision: every node gets a full consumer time from now for its next heartbeat."""
        now = self._clock()
        for node_id in self._bootups:
            self._last.setdefault(node_id, now)
            self._last[node_id] = max(self._last[node_id], now)
        self._armed = True

    def disarm(self) -> None:
        self._armed = False

    def expired(self, now: float | None = None) -> list[tuple[int, float]]:
        """(node ID, seconds since its last heartbeat) of every node past the consumer time."""
        if not self._armed:
            return []
        now = self._clock() if now is None else now
        return [(n, now - t) for n, t in self._last.items() if now - t > self.timeout]

    def state(self, node_id: int) -> int | None:
        """Last NMT state the node reported (None before its first heartbeat)."""
        return self._state[node_id]

    def all_in_state(self, state: int, node_ids: Iterable[int]) -> bool:
        return all(self._state.get(n) == state for n in node_ids)
