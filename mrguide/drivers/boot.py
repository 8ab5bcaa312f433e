"""Boot and teardown of the `Cobot`: open the bus, boot and configure every node, start the control thread;
and the reverse, which always completes.

Boot: NMT reset communication → every boot-up message → SDO configuration (PDO mapping, CSP, the master's
heartbeat as consumer entry 0x1016) → NMT start → every node OPERATIONAL by heartbeat → the control thread
runs → every device answers SYNC with PDO feedback. Teardown: quick-stop moving drives, disable them, end
the devices' supervision of the master, stop the control thread, NMT pre-operational, close the bus.
"""

from __future__ import annotations

import logging
from functools import partial

import can
import canopen
from canopen import RemoteNode
from canopen.sdo.exceptions import SdoError

from mrguide.config import ConfigError
from mrguide.drivers import supervision
from mrguide.drivers.bus import BusReceiver, open_bus
from mrguide.drivers.cia402 import (
    FAULT_STATES,
    OPERATION_ENABLED,
    QUICK_STOP_ACTIVE,
    SWITCH_ON_DISABLED,
    Cia402Drive,
    PowerCommand,
)
from mrguide.drivers.cobot_core import CobotCore
from mrguide.drivers.config import eds_path
from mrguide.drivers.control_loop import ControlLoop
from mrguide.drivers.conversion import JointConversion
from mrguide.drivers.errors import BootError, BusError, NotReadyError
from mrguide.drivers.heartbeat import OPERATIONAL, HeartbeatConsumer, nmt_state_name
from mrguide.drivers.nmt import (
    NMT_RESET_COMMUNICATION,
    NMT_START,
    close_network,
    send_nmt,
    set_master_consumer,
    sign_off,
)
from mrguide.drivers.objects import VACUUM_COMMAND
from mrguide.drivers.od_values import node_id_of
from mrguide.drivers.vacuum import BLOW_OFF_BIT, VACUUM_ON_BIT, VacuumGenerator

logger = logging.getLogger(__name__)


def load_node(node_id: int, eds: str) -> RemoteNode:
    path = eds_path(eds)
    try:
        return RemoteNode(node_id, str(path))
    except Exception as exc:  # configparser, KeyError, ValueError... from a third-party file format
        raise ConfigError(f"EDS file {path} cannot be read for node {node_id}: {exc}") from exc


def connect(core: CobotCore, loop: ControlLoop) -> None:
    """Open the bus, boot and configure every node (NMT + SDO), start the SYNC cycle.

    Returns once every node sends PDO feedback. Raises ConfigError, BusError or BootError; on any failure
    everything started so far is torn down again.
    """
    if core.network is not None:
        raise NotReadyError("already connected")
    core.reset_run_state()
    _open(core)
    try:
        assert core.receiver is not None and core.vacuum is not None
        core.receiver.start()
        _boot(core)
        loop.start()
        devices: list[Cia402Drive | VacuumGenerator] = [*core.drives, core.vacuum]
        if not core.wait_for(lambda: all(d.feedback is not None for d in devices), core.config.timing.boot_timeout):
            silent = [d.label for d in devices if d.feedback is None]
            raise BootError(f"no PDO feedback from {', '.join(silent)} after NMT start")
        core.raise_fault()
    except can.CanError as exc:
        teardown(core, loop)
        raise BusError(f"CAN error during boot on {core.bus_name()}: {exc}") from exc
    except BaseException:
        teardown(core, loop)
        raise
    logger.info(
        "cobot connected on %s: %d drives + vacuum generator, %.1f ms cycle",
        core.bus_name(),
        len(core.drives),
        core.period * 1000,
    )


def _open(core: CobotCore) -> None:
    """The network, its receive thread and heartbeat consumer, and the device objects (nothing sent yet)."""
    cfg = core.config
    nodes = [load_node(j.node_id, cfg.drives.eds) for j in cfg.joints]
    vacuum_node = load_node(cfg.vacuum.node_id, cfg.vacuum.eds)
    network = canopen.Network(open_bus(cfg.bus))
    receiver = BusReceiver(network, "master", cfg.timing.realtime_priority)
    hb = HeartbeatConsumer(cfg.timing.heartbeat_timeout, receiver.horizon)
    core.drives = [
        Cia402Drive(node, name, JointConversion.from_config(joint), cfg.drives, core.current_sync)
        for node, name, joint in zip(nodes, core.joint_names, cfg.joints)
    ]
    core.vacuum = VacuumGenerator(vacuum_node, cfg.vacuum, core.current_sync)
    receiver.expect(0x000, (2,))  # NMT commands from another master: legal, canopen tracks them
    for node in [*nodes, vacuum_node]:
        network.add_node(node)
        nid = node_id_of(node)
        hb.watch(network, nid)
        node.emcy.add_callback(partial(supervision.on_emcy, core, nid))
        receiver.expect(0x700 + nid, (1,))
        receiver.expect(0x080 + nid, (8,))
        receiver.expect(0x580 + nid, (8,))
    core.network, core.receiver, core.hb = network, receiver, hb


def _boot(core: CobotCore) -> None:
    timing = core.config.timing
    hb, receiver, vacuum = core.hb, core.receiver, core.vacuum
    assert hb is not None and receiver is not None and vacuum is not None
    devices: list[Cia402Drive | VacuumGenerator] = [*core.drives, vacuum]
    hb.expect_bootup()
    for dev in devices:
        send_nmt(dev.node.network, NMT_RESET_COMMUNICATION, dev.node_id)
    missing = hb.wait_bootup(timing.boot_timeout)
    if missing:
        labels = ", ".join(core.label(n) for n in missing)
        raise BootError(
            f"no boot-up message from {labels} within {timing.boot_timeout} s after NMT reset "
            f"communication on {core.bus_name()}; check power, wiring, node IDs and bit rate"
        )
    for dev in devices:
        for cob_id, length in dev.configure(timing).items():
            receiver.expect(cob_id, (length,))
        if core.config.master.heartbeat:
            try:
                set_master_consumer(dev.node, core.config.master.node_id, timing.heartbeat_timeout_ms)
            except SdoError as exc:
                raise BootError(
                    f"{dev.label}: cannot make it consume the master's heartbeat (0x1016:01): {exc}; "
                    "set [master] heartbeat = false for devices without 0x1016"
                ) from exc
    vacuum.vacuum_on, vacuum.blow_off = _vacuum_command_on_device(vacuum)
    hb.arm()
    for dev in devices:
        send_nmt(dev.node.network, NMT_START, dev.node_id)
    ids = core.config.node_ids
    if not core.wait_for(lambda: hb.all_in_state(OPERATIONAL, ids), timing.boot_timeout):
        states = ", ".join(f"{core.label(n)}: {nmt_state_name(hb.state(n))}" for n in ids if hb.state(n) != OPERATIONAL)
        raise BootError(f"nodes did not report OPERATIONAL by heartbeat after NMT start: {states}")


def _vacuum_command_on_device(vacuum: VacuumGenerator) -> tuple[bool, bool]:
    """Keep whatever the vacuum generator is doing (a held part must not drop on reconnect)."""
    try:
        bits = vacuum.node.sdo[VACUUM_COMMAND].raw
    except SdoError as exc:
        raise BootError(f"{vacuum.label}: cannot read vacuum command 0x2000: {exc}") from exc
    return bool(bits & VACUUM_ON_BIT), bool(bits & BLOW_OFF_BIT)


def disconnect(core: CobotCore, loop: ControlLoop) -> None:
    """Quick-stop moving drives, disable them, put every node in PRE-OPERATIONAL and close the bus.

    The vacuum command is left as it is (a held part stays held). Never raises: whatever fails on the way
    is logged, and the NMT commands and closing the bus still happen.
    """
    if core.network is None:
        return
    try:
        _stop_and_disable(core, loop)
    except Exception:
        logger.exception("disconnect: stopping and disabling the drives failed; tearing down anyway")
    finally:
        teardown(core, loop)
    logger.info("cobot disconnected")


def _stop_and_disable(core: CobotCore, loop: ControlLoop) -> None:
    """Quick-stop moving drives, wait until they are disabled, end the devices' supervision of the master."""
    if isinstance(core.fault, BusError) or not loop.alive:
        return  # nothing can be sent
    powered = (OPERATION_ENABLED, QUICK_STOP_ACTIVE)
    alive = [d for d in core.drives if d.feedback is not None and not core.misses.get(d.node_id)]
    timeout = core.config.timing.enable_timeout
    if any(core.state(d) in powered for d in alive):
        if not supervision.quick_stop(core):
            logger.error("disconnect: the control thread holds the driver lock; quick stop left to it")
        core.wait_for(lambda: not any(core.state(d) in powered for d in alive), timeout)
    with core.lock.bounded():
        core.command = PowerCommand.DISABLE
    core.wait_for(lambda: all(core.state(d) in (SWITCH_ON_DISABLED, *FAULT_STATES) for d in alive), timeout)
    if core.config.master.heartbeat:
        assert core.hb is not None and core.vacuum is not None
        sign_off((*core.drives, core.vacuum), core.hb, core.config.master.node_id)


def teardown(core: CobotCore, loop: ControlLoop) -> None:
    """Stop the control thread, send NMT pre-operational to every node, close the bus; never cut short."""
    loop.stop()
    core.motion = False  # the control thread is gone (or hung): no lock needed, none waited for
    core.space.set()
    network, core.network = core.network, None
    if network is not None:
        close_network(network, core.config.node_ids, core.hb, core.receiver)
