"""NMT plumbing of the master: command frames, the devices' supervision of the master, closing the network.

NMT commands are sent as raw frames: canopen's `nmt.send_command` looks up the node's last reported NMT
state to log it and raises KeyError after a heartbeat that carried an undefined one. Closing the network
is a sequence of best-effort steps, so one failure never leaves a node OPERATIONAL or the bus open.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable
from functools import partial

import can
import canopen
from canopen import RemoteNode
from canopen.sdo.exceptions import SdoError

from mrguide.drivers.bus import BusReceiver
from mrguide.drivers.cia402 import Cia402Drive
from mrguide.drivers.heartbeat import HeartbeatConsumer, consumer_heartbeat_entry
from mrguide.drivers.objects import CONSUMER_HEARTBEAT_TIME
from mrguide.drivers.vacuum import VacuumGenerator

logger = logging.getLogger(__name__)

NMT_START = 0x01
NMT_PRE_OPERATIONAL = 0x80
NMT_RESET_COMMUNICATION = 0x82


def send_nmt(network: canopen.Network, command: int, node_id: int) -> None:
    """Send NMT `command` to `node_id` (0 = all nodes)."""
    network.send_message(0x000, bytes([command, node_id]))


def set_master_consumer(node: RemoteNode, master_id: int, time_ms: int) -> None:
    """Make a device consume the master's heartbeat with consumer time `time_ms` by SDO (0 switches it off)."""
    node.sdo[CONSUMER_HEARTBEAT_TIME][1].raw = consumer_heartbeat_entry(master_id, time_ms)


def sign_off(devices: Iterable[Cia402Drive | VacuumGenerator], hb: HeartbeatConsumer, master_id: int) -> None:
    """Switch off the supervision of the master in every device that still sends its heartbeat: a planned
    disconnect is no master loss (devices left OPERATIONAL by a fault still answer SDO)."""
    silent = {node_id for node_id, _ in hb.expired()}
    for dev in devices:
        if dev.node_id in silent or hb.state(dev.node_id) is None:
            continue
        try:
            set_master_consumer(dev.node, master_id, 0)
        except (SdoError, can.CanError) as exc:
            logger.warning("%s: could not switch off its supervision of the master's heartbeat: %s", dev.label, exc)


def close_network(
    network: canopen.Network, node_ids: Iterable[int], hb: HeartbeatConsumer | None, receiver: BusReceiver | None
) -> None:
    """Disarm heartbeat supervision, stop the receive thread, NMT pre-operational to every node, close the bus.

    Every step is attempted whatever the previous ones raised (logged).
    """
    if hb is not None:
        _best_effort("disarming the heartbeat consumer", hb.disarm)
    if receiver is not None:
        _best_effort("stopping the CAN receive thread", receiver.stop)
    for node_id in node_ids:
        _best_effort(f"NMT pre-operational to node {node_id}", partial(send_nmt, network, NMT_PRE_OPERATIONAL, node_id))
    _best_effort("closing the CAN bus", network.disconnect)


def _best_effort(what: str, action: Callable[[], object]) -> None:
    try:
        action()
    except Exception as exc:
        logger.warning("%s failed: %r", what, exc)
