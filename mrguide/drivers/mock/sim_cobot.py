"""The simulated cobot: six CiA 402 drives and the vacuum generator as CANopen slaves on one bus.

All devices share one python-can bus (normally the in-process `virtual` interface, on the channel of the
cobot's bus config) wrapped in fault injection, and one plant that is stepped once per SYNC from the
simulator's receive thread (the world's time advances with SYNC). The devices judge the master's heartbeat on the
bus clock (`BusReceiver.horizon`): at every SYNC, in frame order, and from a device clock thread, which must also
fire when no SYNC comes::

    plant = FirstOrderPlant(robot.q_home)
    with SimulatedCobot(config, plant) as sim:      # devices boot and wait in PRE-OPERATIONAL
        with Cobot(config) as cobot:                # the master finds them on the same channel
            ...
            sim.faults.set_drop_rate(0.05)          # fault injection while running
            sim.inject_drive_fault(5)
"""

from __future__ import annotations

import logging
import math
import threading
import time
from dataclasses import dataclass, replace

import canopen
import numpy as np

from mrguide.config import ConfigError
from mrguide.drivers.bus import BusReceiver, ReceiverStats, open_bus
from mrguide.drivers.config import CobotBusConfig, eds_path
from mrguide.drivers.conversion import JointConversion
from mrguide.drivers.errors import NotReadyError
from mrguide.drivers.mock.drive_sim import SimulatedDrive
from mrguide.drivers.mock.faults import FaultInjector, FaultStats, FaultyBus
from mrguide.drivers.mock.sync_backlog import SyncBacklog
from mrguide.drivers.mock.vacuum_sim import SimulatedVacuumGenerator
from mrguide.plant import Plant

logger = logging.getLogger(__name__)

#: EMCY code for an injected drive fault: 0x2310 continuous over-current (CiA 402).
DEFAULT_FAULT_CODE = 0x2310
#: Period of the devices' own clock that checks their heartbeat consumers (s).
DEVICE_CLOCK_PERIOD = 0.01


#: How long the simulated devices may go without sending feedback before the master calls it lost (s).
SHARED_PC_FEEDBACK_TOLERANCE_S = 1.0


def shared_pc_config(config: CobotBusConfig) -> CobotBusConfig:
    """The master's bus config when the simulated devices run on the same PC.

    They share the CPU (and Python's GIL) with the master on an OS without real-time guarantees: the
    control and receive threads get SCHED_FIFO where allowed, and the supervision tolerates 1 s
    without feedback (real bus: 5 cycles, 20 ms) and 0.45 s without heartbeat (real bus: 0.18 s), so that a
    busy machine is not mistaken for a dead drive: with two trainings beside it, a simulated drive has gone
    unscheduled for more than 100 ms. Injected faults still trip them.
    """
    t = config.timing
    feedback_cycles = math.ceil(SHARED_PC_FEEDBACK_TOLERANCE_S / t.control_period)
    return replace(
        config,
        timing=replace(
            t,
            realtime_priority=t.realtime_priority or 50,
            max_missed_feedback=min(max(t.max_missed_feedback, feedback_cycles), 1000),  # the config allows 1000
            heartbeat_timeout_factor=3.0,
            heartbeat_period=max(t.heartbeat_period, 0.15),
        ),
    )


@dataclass(frozen=True)
class SimStats:
    syncs: int
    receiver: ReceiverStats
    faults: FaultStats


class SimulatedCobot:
    """CANopen slaves of the cobot on a CAN bus, with one plant behind them."""

    def __init__(self, config: CobotBusConfig, plant: Plant, seed: int = 0) -> None:
        if plant.dof != len(config.joints):
            raise ConfigError(f"joints: {len(config.joints)} drives configured, the plant has {plant.dof} joints")
        self.config = config
        self.plant = plant
        self.faults = FaultInjector(seed)
        #: Held while a SYNC is processed (plant stepping); take it to touch the plant from another thread.
        self.lock = threading.RLock()
        self.sync_count = 0
        #: How far the world (one control period per SYNC) runs behind the wall clock (`sync_backlog`).
        self.backlog = SyncBacklog(config.timing.control_period)
        self._network: canopen.Network | None = None
        self._receiver: BusReceiver | None = None
        self.drives: list[SimulatedDrive] = []
        self.vacuum: SimulatedVacuumGenerator | None = None
        self._clock_thread: threading.Thread | None = None
        self._stop_clock = threading.Event()

    def start(self) -> None:
        """Join the bus and power the devices on (boot-up messages, PRE-OPERATIONAL)."""
        if self._network is not None:
            raise NotReadyError("simulated cobot already started")
        cfg = self.config
        network = canopen.Network(FaultyBus(open_bus(cfg.bus), self.faults))
        receiver = BusReceiver(network, "simulator")
        receiver.expect(0x000, (2,))
        receiver.expect(0x080, (0, 1))
        network.subscribe(0x080, self._on_sync)
        self.drives = [
            SimulatedDrive(
                j.node_id, eds_path(cfg.drives.eds), network, receiver, self.faults, JointConversion.from_config(j)
            )
            for j in cfg.joints
        ]
        self.vacuum = SimulatedVacuumGenerator(
            cfg.vacuum.node_id, eds_path(cfg.vacuum.eds), network, receiver, self.faults
        )
        self._network, self._receiver = network, receiver
        receiver.start()
        for slave in (*self.drives, self.vacuum):
            slave.power_on()
        self._stop_clock.clear()
        self._clock_thread = threading.Thread(target=self._device_clock, name="sim-device-clock", daemon=True)
        self._clock_thread.start()
        logger.info(
            "simulated cobot on %s:%s: drives %s, vacuum generator %d",
            cfg.bus.interface,
            cfg.bus.channel,
            [d.node_id for d in self.drives],
            self.vacuum.node_id,
        )

    def stop(self) -> None:
        """Leave the bus (heartbeats stop, the bus is shut down)."""
        self._stop_clock.set()
        if self._clock_thread is not None:
            self._clock_thread.join()
            self._clock_thread = None
        network, self._network = self._network, None
        if network is not None:
            assert self._receiver is not None
            self._receiver.stop()
            network.disconnect()

    def __enter__(self) -> SimulatedCobot:
        self.start()
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    def inject_drive_fault(self, node_id: int, code: int = DEFAULT_FAULT_CODE) -> None:
        """The drive faults at the next SYNC and sends EMCY `code`; a fault reset clears it."""
        for drive in self.drives:
            if drive.node_id == node_id:
                drive.inject_fault(code)
                return
        raise ValueError(f"no simulated drive with node ID {node_id}")

    def set_vacuum_leak(self, fraction: float) -> None:
        """A leak in the vacuum line (0 = tight, 1 = no vacuum builds)."""
        with self.lock:
            self.plant.set_vacuum_leak(fraction)

    def stats(self) -> SimStats:
        assert self._receiver is not None, "start() first"
        return SimStats(self.sync_count, self._receiver.stats(), self.faults.stats())

    def _device_clock(self) -> None:
        assert self.vacuum is not None and self._receiver is not None
        slaves, receiver = (*self.drives, self.vacuum), self._receiver
        while not self._stop_clock.wait(DEVICE_CLOCK_PERIOD):
            now = receiver.horizon()
            with self.lock:
                for slave in slaves:
                    if not slave.silent:
                        slave.check_heartbeats(now)

    def _on_sync(self, can_id: int, data: bytearray, timestamp: float) -> None:
        assert self.vacuum is not None
        with self.lock:
            for slave in (*self.drives, self.vacuum):  # in frame order: a SYNC after a silent master finds it lost
                if not slave.silent:
                    slave.check_heartbeats(timestamp)
            self.sync_count += 1
            self.backlog.tick(time.monotonic())
            plant = self.plant
            dt = self.drives[0].interpolation_period
            q, v = plant.joint_positions(), plant.joint_velocities()
            targets = np.empty_like(q)
            for i, drive in enumerate(self.drives):
                if drive.silent:
                    targets[i] = drive.hold(q[i])
                    continue
                drive.refresh_pdos()
                drive.apply_rpdos()
                targets[i] = drive.cycle(q[i], v[i], dt)
                if drive.operational:
                    drive.transmit_tpdos(self.sync_count)
            vacuum = self.vacuum
            if not vacuum.silent:
                vacuum.refresh_pdos()
                vacuum.apply_rpdos()
                vacuum.cycle(plant.vacuum_level_kpa())
                if vacuum.operational:
                    vacuum.transmit_tpdos(self.sync_count)
            plant.set_joint_targets(targets)
            plant.set_vacuum(*vacuum.commands())
            plant.step(dt)
