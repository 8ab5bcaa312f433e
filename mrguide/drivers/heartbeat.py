"""Heartbeat consumer with a timeout, boot-up detection, and the devices' view of the master's heartbeat.

canopen's `NmtMaster` records each node's last heartbeat state but never times out. This consumer
hooks the same heartbeat frames (through `nmt.add_heartbeat_callback`), stamps them with a monotonic
clock and reports nodes whose heartbeat is older than the consumer time.

The other direction: the master produces a heartbeat too, and every device consumes it through its
object 0x1016 (CiA 301), so a device notices a dead or hung master by itself.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable
from functools import partial

from canopen import RemoteNode
from canopen.nmt import NMT_STATES

from mrguide.drivers.od_values import node_id_of

#: NMT state reported in a boot-up message.
BOOTUP = 0
#: NMT state OPERATIONAL as carried in heartbeats.
OPERATIONAL = 5
#: Consumer heartbeat time object (CiA 301); sub-index 1 holds the entry for the master.
CONSUMER_HEARTBEAT = 0x1016
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


class HeartbeatConsumer:
    """Tracks heartbeat age and NMT state per node; supervision starts when `arm()` is called."""

    def __init__(self, timeout: float, clock: Callable[[], float] = time.monotonic) -> None:
        self.timeout = timeout
        self._clock = clock
        self._last: dict[int, float] = {}
        self._state: dict[int, int | None] = {}
        self._bootups: dict[int, threading.Event] = {}
        self._armed = False

    def watch(self, node: RemoteNode) -> None:
        """Start following the heartbeats of `node`."""
        nid = node_id_of(node)
        self._state[nid] = None
        self._bootups[nid] = threading.Event()
        node.nmt.add_heartbeat_callback(partial(self._on_heartbeat, nid))

    def _on_heartbeat(self, node_id: int, state: int) -> None:
        self._last[node_id] = self._clock()
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
