"""Supervision of the bus and the devices, and the fault latch, for the `Cobot`.

The control thread calls `check_feedback` and `supervise` every cycle: every device must answer each SYNC
with its status TPDO, keep its heartbeat and stay NMT OPERATIONAL, and no drive may fault or leave
OPERATION ENABLED while streaming. The first fault is latched (`latch`): every drive gets quick stop,
streaming ends, and the next facade call raises it. Other threads never take the lock to do so: the
receive thread posts EMCY faults (`on_emcy`) and the application posts quick stops (`quick_stop`) to the
lock's mailbox, which the control thread drains at the start of every cycle (`apply_requests`).
"""

from __future__ import annotations

import logging
import time

from canopen.emcy import EmcyError

from mrguide.drivers.cia402 import FAULT_STATES, OPERATION_ENABLED, Cia402Drive, PowerCommand
from mrguide.drivers.cobot_core import CobotCore
from mrguide.drivers.errors import (
    BusOffError,
    DeviceFaultError,
    DriverError,
    FeedbackLostError,
    HeartbeatLostError,
    NodeLostError,
)
from mrguide.drivers.heartbeat import OPERATIONAL, nmt_state_name
from mrguide.drivers.vacuum import VacuumGenerator

logger = logging.getLogger(__name__)


def latch(core: CobotCore, error: DriverError) -> None:
    """Keep the first fault and quick-stop; control thread only (other threads post to the lock)."""
    with core.lock:
        if core.fault is None:
            core.fault = error
            core.fault_at = time.monotonic()
            core.command = PowerCommand.QUICK_STOP
            logger.error("cobot fault, quick stop: %s", error)
        halt(core)


def halt(core: CobotCore) -> None:
    """Streaming ends: queued setpoints are dropped and a blocked `stream` wakes up; lock held."""
    core.motion = False
    core.queue.clear()
    core.space.set()


def apply_requests(core: CobotCore) -> None:
    """Carry out the quick stops and faults other threads posted without the lock; lock held."""
    for request in core.lock.drain():
        if request is None:
            core.command = PowerCommand.QUICK_STOP
            halt(core)
        else:
            latch(core, request)


def quick_stop(core: CobotCore) -> bool:
    """Post a quick stop and carry it out now if the lock can be had; False if the control thread hangs
    holding it (the request then waits for that thread's next cycle)."""
    core.lock.post(None)
    if not core.lock.acquire(timeout=core.lock.timeout):
        return False
    try:
        apply_requests(core)
    finally:
        core.lock.release()
    return True


def check_feedback(core: CobotCore) -> None:
    """Every device must have answered the previous SYNC with its status TPDO. Judged only once the receiver has
    dispatched what arrived up to when that SYNC went out (its horizon): a receive thread behind its queue has the
    answers waiting in it, and they are not missing."""
    assert core.receiver is not None
    if not core.sync_sent or core.receiver.horizon() < core.sync_wall:
        return
    assert core.vacuum is not None
    limit = core.config.timing.max_missed_feedback
    devices: tuple[Cia402Drive | VacuumGenerator, ...] = (*core.drives, core.vacuum)
    for dev in devices:
        node_id = dev.node_id
        if dev.rx_count != core.last_rx.get(node_id):
            core.last_rx[node_id] = dev.rx_count
            core.misses[node_id] = 0
            continue
        core.lost_feedback += 1
        core.misses[node_id] = core.misses.get(node_id, 0) + 1
        if core.misses[node_id] == limit:
            latch(
                core,
                FeedbackLostError(
                    f"{core.label(node_id)}: no TPDO for {limit} consecutive SYNC cycles", node_id, core.name(node_id)
                ),
            )


def supervise(core: CobotCore) -> None:
    """Bus-off, heartbeats, NMT states and drive power states; any problem is latched."""
    assert core.receiver is not None and core.hb is not None
    if core.receiver.bus_off:
        latch(core, BusOffError(f"CAN controller on {core.bus_name()} is bus-off"))
    expired = dict(core.hb.expired())
    core.lost_logged &= expired.keys()
    for node_id, age in expired.items():
        if node_id not in core.lost_logged:
            core.lost_logged.add(node_id)
            latch(
                core,
                HeartbeatLostError(
                    f"heartbeat of {core.label(node_id)} lost: none for {age * 1000:.0f} ms "
                    f"(consumer time {core.hb.timeout * 1000:.0f} ms)",
                    node_id,
                    core.name(node_id),
                ),
            )
    for node_id in core.config.node_ids:
        nmt_state = core.hb.state(node_id)
        if nmt_state is not None and nmt_state != OPERATIONAL:
            latch(
                core,
                NodeLostError(
                    f"{core.label(node_id)} left NMT OPERATIONAL: reports {nmt_state_name(nmt_state)}",
                    node_id,
                    core.name(node_id),
                ),
            )
    for drive in core.drives:
        state = core.state(drive)
        if state in FAULT_STATES:
            latch(core, DeviceFaultError(f"{drive.label} is in {state}", drive.node_id, drive.name, None))
        elif core.motion and state != OPERATION_ENABLED:
            latch(core, DriverError(f"{drive.label} left {OPERATION_ENABLED}: now {state}"))


def on_emcy(core: CobotCore, node_id: int, emcy: EmcyError) -> None:
    """EMCY callback (receive thread): an active error is posted as a fault for the control thread to latch."""
    core.emcy_count += 1
    if emcy.code & 0xFF00 == 0:
        logger.info("%s: EMCY error reset", core.label(node_id))
        return
    text = f"{core.label(node_id)}: EMCY 0x{emcy.code:04X} ({emcy.get_desc()}), error register 0x{emcy.register:02X}"
    if emcy.register:  # latched by the control thread at its next cycle (this is the receive thread)
        core.lock.post(DeviceFaultError(text, node_id, core.name(node_id), emcy.code))
    else:
        logger.warning("%s (no active error)", text)
