"""Read-only snapshots the `Cobot` facade hands out: joint and vacuum state, per-cycle samples, status."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mrguide.drivers.cycle import MissAnatomy
from mrguide.drivers.errors import DriverError


@dataclass(frozen=True)
class JointState:
    """Latest joint feedback in robot joint order."""

    #: Joint positions (rad).
    positions: np.ndarray
    #: Joint velocities (rad/s); from TPDO2, or zeros when the velocity TPDO is not mapped.
    velocities: np.ndarray
    #: CiA 402 power state of each drive, e.g. "OPERATION ENABLED".
    drive_states: tuple[str, ...]
    #: Oldest SYNC cycle number these samples answer (the last SYNC sent before they arrived).
    sync_index: int
    #: Seconds since the oldest sample arrived.
    age: float


@dataclass(frozen=True)
class VacuumState:
    """Latest vacuum-generator feedback and the command currently sent."""

    #: Vacuum level in kPa below atmosphere (0 = atmospheric, positive = vacuum).
    level_kpa: float
    part_gripped: bool
    part_lost: bool
    vacuum_on: bool
    blow_off: bool
    age: float


@dataclass(frozen=True)
class CycleSample:
    """What one control cycle did; handed to cycle observers from the control thread."""

    cycle: int
    #: SYNC transmission time minus its deadline (s).
    lateness: float
    #: Joint setpoint (rad) taken from the queue this cycle, None when holding or not streaming.
    setpoint: np.ndarray | None
    #: Latest measured joint positions (rad).
    positions: np.ndarray
    #: Per joint, the SYNC cycle number its measured position answers.
    feedback_sync: np.ndarray


@dataclass(frozen=True)
class DriverStats:
    """Counters since `connect()`; lateness in seconds."""

    cycles: int
    missed_cycles: int
    lateness_p50: float
    lateness_p99: float
    lateness_max: float
    #: A cycle's work (s), its start to the end of its observers: 99th percentile and maximum.
    work_p99: float
    work_max: float
    #: Cycles whose work took longer than one period: a missed cycle after one was the process's own work (or a
    #: wait for the GIL) running long, a missed cycle without one a late wake-up.
    work_overruns: int
    frames_tx: int
    bits_tx: int
    frames_rx: int
    bits_rx: int
    #: Expected synchronous TPDOs that had not arrived by the next cycle.
    lost_feedback: int
    #: Cycles where the setpoint queue ran dry while the arm was moving (setpoint held).
    underruns: int
    refused_setpoints: int
    unknown_frames: int
    bad_length_frames: int
    error_frames: int
    emcy_received: int
    #: The gaps between control cycle starts that skipped deadlines: where the control thread's time went.
    misses: MissAnatomy = field(default_factory=MissAnatomy)


@dataclass(frozen=True)
class CobotStatus:
    connected: bool
    #: All drives in OPERATION ENABLED and streaming allowed.
    enabled: bool
    drive_states: dict[str, str]
    nmt_states: dict[int, str]
    #: Latched fault (first one since connect/reset), or None.
    fault: DriverError | None
    #: time.monotonic() when the fault was latched.
    fault_at: float | None
    #: Node IDs whose heartbeat is currently older than the consumer time.
    heartbeat_lost: tuple[int, ...]
    stats: DriverStats
