"""Bus description of the cobot: CAN interface, control timing, node IDs, EDS files, unit conversions.

Loaded from a TOML file (`configs/devices/cobot_bus.toml`) into frozen dataclasses with defaults. What belongs to
the arm is not repeated here: the number of drives, the joint <-> node-ID map and the joint limits come from
the arm file (`mrguide.robot.load_robot()`); `[limits]` may only tighten the limits.
No value in this file comes from the paper (it says nothing about the bus); values marked "assumed"
are engineering choices, not datasheet figures.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

import can.interfaces
import numpy as np

from mrguide.config import ConfigError, Range, check_number, check_ranges, from_dict, load_toml
from mrguide.drivers.bus_options import check_bus_options
from mrguide.drivers.eds_check import DRIVE_OBJECTS, VACUUM_OBJECTS, VELOCITY_TPDO_OBJECTS, check_eds
from mrguide.robot import RobotSpec, load_robot

#: Directory of the EDS files shipped with the package (also read by the simulated devices).
EDS_DIR = Path(__file__).resolve().parent / "eds"

#: Bit rates defined by CiA 301 for classic CAN (bit/s).
CIA301_BITRATES = (10_000, 20_000, 50_000, 125_000, 250_000, 500_000, 800_000, 1_000_000)

INT32_MAX = 2**31 - 1

#: Smallest heartbeat consumer time / producer time accepted: one lost heartbeat plus half a period of
#: jitter. At 2.0 a single lost or late heartbeat trips the consumer (5 % frame loss quick-stopped the
#: arm within seconds); CiA 301 practice pads the ratio (>= 1.5-3 x plus jitter).
MIN_HEARTBEAT_FACTOR = 2.5
MAX_HEARTBEAT_FACTOR = 10.0


def eds_path(name: str) -> Path:
    """Resolve an EDS file name: absolute paths as given, relative ones inside `mrguide/drivers/eds/`."""
    path = Path(name)
    return path if path.is_absolute() else EDS_DIR / path


def _check_node_id(node_id: int, where: str) -> None:
    if not 1 <= node_id <= 127:
        raise ConfigError(f"{where}: CANopen node ID must be 1..127, got {node_id}")


@dataclass(frozen=True)
class BusConfig:
    """python-can bus: interface, channel and bit rate ([bus])."""

    #: python-can interface name: virtual (in-process, no hardware), socketcan, pcan, kvaser, slcan, ...
    interface: str = "virtual"
    #: Interface channel, e.g. "can0" (socketcan), "PCAN_USBBUS1" (pcan); any name for virtual.
    channel: str = "mrguide"
    #: Bit rate (bit/s). Assumed 1 Mbit/s, the highest CiA 301 classic-CAN rate.
    bitrate: int = 1_000_000
    #: Extra keyword arguments for `can.Bus`, e.g. {tty_baudrate = 115200} for slcan.
    options: dict[str, str | int | float | bool] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.interface not in can.interfaces.VALID_INTERFACES:
            known = ", ".join(sorted(can.interfaces.VALID_INTERFACES))
            raise ConfigError(f"bus.interface: unknown python-can interface {self.interface!r}; known: {known}")
        if self.bitrate not in CIA301_BITRATES:
            raise ConfigError(f"bus.bitrate: {self.bitrate} is not a CiA 301 bit rate {CIA301_BITRATES}")
        reserved = {"interface", "channel", "bitrate"} & set(self.options)
        if reserved:
            raise ConfigError(f"bus.options: set {sorted(reserved)} as bus keys, not options")
        check_bus_options(self.interface, self.options)


@dataclass(frozen=True)
class TimingConfig:
    """Control cycle and supervision times ([timing]); all in seconds."""

    #: SYNC / control period. 4 ms (250 Hz) is the project's requirement for CSP streaming.
    control_period: Annotated[float, Range(0.0005, 0.1, " s")] = 0.004
    #: Producer heartbeat time written to every node's 0x1017, and the master's own heartbeat period
    #: (whole ms, a whole number of control periods for the master's to be exact; assumed).
    heartbeat_period: Annotated[float, Range(0.001, 65.535, " s")] = 0.04
    #: Heartbeat consumer time = factor x producer time, in both directions (the master consumes the
    #: devices', every device the master's via 0x1016). 4.5 = three lost heartbeats in a row plus half a
    #: period of jitter: 180 ms at 40 ms (see configs/devices/cobot_bus.toml); at least MIN_HEARTBEAT_FACTOR.
    heartbeat_timeout_factor: Annotated[
        float,
        Range(
            MIN_HEARTBEAT_FACTOR,
            MAX_HEARTBEAT_FACTOR,
            " (consumer time / producer time: one lost heartbeat plus jitter at least)",
        ),
    ] = 4.5
    #: Time allowed for all nodes to send their boot-up message after NMT reset communication; [0.01, 60].
    boot_timeout: Annotated[float, Range(0.01, 60.0, " s")] = 3.0
    #: Time allowed for all drives to reach OPERATION ENABLED (or to leave FAULT on reset); [0.01, 60].
    enable_timeout: Annotated[float, Range(0.01, 60.0, " s")] = 1.0
    #: SDO response timeout per request during configuration; [0.001, 10].
    sdo_timeout: Annotated[float, Range(0.001, 10.0, " s")] = 0.3
    #: Joint setpoints buffered ahead of the bus (cycles, 1..1000); `Cobot.stream` blocks when full.
    setpoint_queue_depth: Annotated[int, Range(1, 1000, " cycles")] = 4
    #: Consecutive SYNC cycles without a node's TPDO before it counts as lost (1..1000).
    max_missed_feedback: Annotated[int, Range(1, 1000, " cycles")] = 5
    #: SCHED_FIFO priority (1..99) of the control and receive threads; 0 = normal scheduling (Linux only).
    realtime_priority: Annotated[int, Range(0, 99)] = 0
    #: Python's thread switch interval while the control thread runs (s, 0..0.005): how long it can wait for the GIL
    #: that another thread of the process holds before that thread is made to let go. 0 leaves the interpreter's
    #: (5 ms, longer than a control period); 0.5 ms cut the control cycles whose work ran past the period about
    #: sixfold in the camera cell (docs/performance.md).
    switch_interval: Annotated[float, Range(0.0, 0.005, " s")] = 0.0005

    def __post_init__(self) -> None:
        # Every value arms a supervision: NaN or inf would switch it off (a time-out that never expires).
        check_ranges(self, "timing")
        hb_ms = self.heartbeat_period * 1000.0
        if abs(hb_ms - round(hb_ms)) > 1e-9:
            raise ConfigError(f"timing.heartbeat_period = {self.heartbeat_period}: must be whole ms")
        if self.heartbeat_period < 2 * self.control_period:
            raise ConfigError("timing.heartbeat_period must be at least two control periods")
        if self.heartbeat_timeout_ms > 0xFFFF:
            raise ConfigError(
                "timing: heartbeat_period x heartbeat_timeout_factor must fit 65.535 s (the devices "
                "consume the master's heartbeat with this time)"
            )

    @property
    def heartbeat_ms(self) -> int:
        return round(self.heartbeat_period * 1000.0)

    @property
    def heartbeat_timeout(self) -> float:
        return self.heartbeat_period * self.heartbeat_timeout_factor

    @property
    def heartbeat_timeout_ms(self) -> int:
        """Consumer time in whole ms, rounded up (written to the devices' 0x1016 for the master)."""
        return math.ceil(round(self.heartbeat_timeout * 1000.0, 6))


@dataclass(frozen=True)
class JointDriveConfig:
    """One joint's drive ([[joints]], in joint order): node ID (from the arm file) and counts <-> radians."""

    node_id: int
    #: Motor encoder counts per motor revolution (assumed 17-bit single-turn encoder).
    encoder_resolution: int = 131072
    #: Motor revolutions per joint revolution (assumed 101:1 strain-wave gear).
    gear_ratio: float = 101.0
    #: Joint angle (rad) at position 0 counts.
    offset: float = 0.0
    #: +1 if counts grow with the joint angle, -1 if the drive counts the other way.
    direction: int = 1

    def __post_init__(self) -> None:
        _check_node_id(self.node_id, "joints.node_id")
        where = f"joints (node {self.node_id})"
        check_number(f"{where}.encoder_resolution", self.encoder_resolution, 1, INT32_MAX, " counts/rev", integer=True)
        check_number(f"{where}.gear_ratio", self.gear_ratio, 1e-3, 1e6)
        check_number(f"{where}.offset", self.offset, -100.0, 100.0, " rad")
        if self.direction not in (1, -1):
            raise ConfigError(f"joints (node {self.node_id}).direction must be 1 or -1, got {self.direction}")


def _default_joints() -> tuple[JointDriveConfig, ...]:
    """One drive with default conversions per joint of the default arm, at its node IDs."""
    return tuple(JointDriveConfig(node_id=n) for n in load_robot().node_ids)


@dataclass(frozen=True)
class DriveConfig:
    """Settings shared by all CiA 402 joint drives ([drives])."""

    eds: str = "cia402_drive.eds"
    #: Following-error window (rad, [1e-4, 1]), written to 0x6065 in counts (assumed).
    following_error_window: Annotated[float, Range(1e-4, 1.0, " rad")] = 0.05
    #: Following-error time-out (ms), 0x6066 (assumed).
    following_error_timeout_ms: Annotated[int, Range(0, 65535, " ms")] = 20
    #: Quick-stop option code 0x605A: 2 = stop on the quick-stop ramp, then SWITCH ON DISABLED.
    quick_stop_option: int = 2
    #: Quick-stop deceleration (rad/s^2, [0.1, 1000]), written to 0x6085 in counts/s^2 (assumed).
    quick_stop_deceleration: Annotated[float, Range(0.1, 1000.0, " rad/s^2")] = 10.0
    #: Also map velocity actual value (0x606C) into a second TPDO every cycle.
    velocity_tpdo: bool = True

    def __post_init__(self) -> None:
        check_eds(
            eds_path(self.eds), DRIVE_OBJECTS + (VELOCITY_TPDO_OBJECTS if self.velocity_tpdo else ()), "drives.eds"
        )
        check_ranges(self, "drives")
        if self.quick_stop_option not in (1, 2, 5, 6):
            raise ConfigError(f"drives.quick_stop_option: {self.quick_stop_option} not supported (1, 2, 5 or 6)")


@dataclass(frozen=True)
class VacuumNodeConfig:
    """Vacuum generator node ([vacuum]); levels in kPa below atmosphere."""

    node_id: int = 16
    eds: str = "vacuum_generator.eds"
    #: Part-gripped threshold L1 (kPa), as on COVAL LEMCOM units; value assumed.
    grip_threshold_kpa: float = 35.0
    #: Hysteresis h1 below L1 (kPa) before "part lost"; value assumed.
    grip_hysteresis_kpa: float = 5.0

    def __post_init__(self) -> None:
        _check_node_id(self.node_id, "vacuum.node_id")
        check_eds(eds_path(self.eds), VACUUM_OBJECTS, "vacuum.eds")
        if not 0 < self.grip_threshold_kpa < 101.3:
            raise ConfigError("vacuum.grip_threshold_kpa must lie in (0, 101.3) kPa")
        if not 0 <= self.grip_hysteresis_kpa < self.grip_threshold_kpa:
            raise ConfigError("vacuum.grip_hysteresis_kpa must lie in [0, grip_threshold_kpa)")


@dataclass(frozen=True)
class MasterConfig:
    """The master (this PC) as a CANopen node ([master])."""

    #: Node ID of the master's heartbeat (0x700 + ID); must differ from every device's.
    node_id: int = 127
    #: Send a heartbeat from the control thread and make every device consume it (0x1016): if the
    #: control thread stops, the devices leave OPERATIONAL and the drives disable by themselves.
    heartbeat: bool = True

    def __post_init__(self) -> None:
        _check_node_id(self.node_id, "master.node_id")


@dataclass(frozen=True)
class LimitOverrides:
    """Optional tighter joint limits ([limits]); empty = the robot spec's limits."""

    q_lower: tuple[float, ...] = ()
    q_upper: tuple[float, ...] = ()
    v_max: tuple[float, ...] = ()


@dataclass(frozen=True)
class CobotBusConfig:
    """The whole bus description of the cobot (one TOML file)."""

    bus: BusConfig = field(default_factory=BusConfig)
    timing: TimingConfig = field(default_factory=TimingConfig)
    joints: tuple[JointDriveConfig, ...] = field(default_factory=_default_joints)
    drives: DriveConfig = field(default_factory=DriveConfig)
    vacuum: VacuumNodeConfig = field(default_factory=VacuumNodeConfig)
    limits: LimitOverrides = field(default_factory=LimitOverrides)
    master: MasterConfig = field(default_factory=MasterConfig)

    def __post_init__(self) -> None:
        ids = [j.node_id for j in self.joints] + [self.vacuum.node_id, self.master.node_id]
        dupes = sorted({n for n in ids if ids.count(n) > 1})
        if dupes:
            raise ConfigError(f"node IDs must be unique (devices and master.node_id), duplicated: {dupes}")

    @property
    def node_ids(self) -> tuple[int, ...]:
        return tuple(j.node_id for j in self.joints) + (self.vacuum.node_id,)


@dataclass(frozen=True)
class JointLimits:
    """Limits the driver enforces on every setpoint (rad, rad/s)."""

    q_lower: np.ndarray
    q_upper: np.ndarray
    v_max: np.ndarray


def load_cobot_bus_config(path: str | Path | None, robot: RobotSpec | None = None) -> CobotBusConfig:
    """Load a bus description from TOML for `robot` (default: the default arm); None gives the defaults (virtual
    bus). Each joint's drive gets the node ID of the arm file's map; the config is checked against the arm
    (`resolve_limits`: one drive per joint, limits). Errors name the file."""
    robot = robot or load_robot()
    where = str(path) if path is not None else "default bus config"
    data = {} if path is None else load_toml(path)
    entries = data.get("joints", [{}] * robot.dof)
    if not isinstance(entries, list) or not all(isinstance(e, dict) for e in entries):
        raise ConfigError(f"{where}: joints must be [[joints]] tables, one per joint of the arm")
    for i, entry in enumerate(entries):
        if "node_id" in entry:
            raise ConfigError(
                f"{where}: joints[{i}].node_id: node IDs come from the arm file's can_nodes "
                f"({robot.arm_file}), not from the bus config"
            )
    if len(entries) != robot.dof:
        raise ConfigError(
            f"{where}: joints: {len(entries)} drives configured, robot {robot.name} has {robot.dof} joints"
        )
    data = {**data, "joints": [{"node_id": n, **e} for n, e in zip(robot.node_ids, entries)]}
    config = from_dict(CobotBusConfig, data, where=where)
    try:
        resolve_limits(config, robot)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {exc}") from exc
    return config


def resolve_limits(config: CobotBusConfig, robot: RobotSpec) -> JointLimits:
    """Joint limits from the robot spec, tightened by `[limits]`; checks they fit the drives' int32 counts."""
    if len(config.joints) != robot.dof:
        raise ConfigError(f"joints: {len(config.joints)} drives configured, robot {robot.name} has {robot.dof} joints")
    limits = {"q_lower": robot.q_lower.copy(), "q_upper": robot.q_upper.copy(), "v_max": robot.v_max.copy()}
    for key, base in limits.items():
        override = getattr(config.limits, key)
        if not override:
            continue
        arr = np.asarray(override, dtype=float)
        if arr.shape != base.shape or not np.all(np.isfinite(arr)):
            raise ConfigError(f"limits.{key}: expected {robot.dof} finite values, got {list(override)}")
        looser = arr < base if key == "q_lower" else arr > base
        if np.any(looser):
            names = [robot.joint_names[i] for i in np.flatnonzero(looser)]
            raise ConfigError(f"limits.{key}: may only tighten the robot limits; looser for {names}")
        limits[key] = arr
    if np.any(limits["q_upper"] <= limits["q_lower"]) or np.any(limits["v_max"] <= 0):
        raise ConfigError("limits: need q_upper > q_lower and v_max > 0 for every joint")
    for joint, name, lo, hi in zip(config.joints, robot.joint_names, limits["q_lower"], limits["q_upper"]):
        counts_per_rad = joint.encoder_resolution * joint.gear_ratio / (2 * math.pi)
        worst = max(abs(lo - joint.offset), abs(hi - joint.offset)) * counts_per_rad
        if worst > INT32_MAX:
            raise ConfigError(f"joints (node {joint.node_id}, {name}): limits reach {worst:.3g} counts, beyond int32")
    return JointLimits(**limits)
