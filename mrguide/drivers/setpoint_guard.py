"""The last checks before the bus: streamed setpoints, and what every drive's RPDO carries.

`setpoint_array` takes a streamed setpoint only if it holds real numbers. `setpoint_problem` validates a streamed joint setpoint before it enters the queue. `plan_rpdos` decides,
every cycle, the controlword and the target of every drive's RPDO, whatever produced the target (a
streamed or held setpoint, or the measured position sent back while enabling, quick-stopping, resetting
a fault or disabling). A target that is non-finite or outside the joint limits never goes out: every
drive gets the quick-stop command instead (a non-enabling controlword), the refused drives an in-limit
target, and the caller latches a fault. Both are pure functions.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from mrguide.drivers.cia402 import PowerCommand, controlword_for
from mrguide.drivers.config import JointLimits

#: Relative slack on the per-cycle step limit (floating-point round-off of trajectory generators).
STEP_SLACK = 1e-6


def setpoint_array(q: object) -> np.ndarray:
    """`q` as a new float array; TypeError unless it holds real numbers only (np.array(dtype=float) would drop
    the imaginary part of a complex value, and a bool or a string is no joint position)."""
    a = np.asarray(q)
    if a.dtype.kind not in "iuf":
        raise TypeError(f"expected real numbers (rad), got {a.dtype} values")
    return np.array(a, dtype=float)


def setpoint_problem(
    q: np.ndarray, reference: np.ndarray, limits: JointLimits, period: float, names: Sequence[str]
) -> str | None:
    """Why joint setpoint `q` (rad) may not follow `reference` one control period later, or None."""
    if q.shape != (len(names),):
        return f"shape {q.shape}, expected ({len(names)},) joint positions in rad"
    bad = ~np.isfinite(q)
    if bad.any():
        return "non-finite value for " + ", ".join(f"{names[int(i)]} ({q[i]})" for i in np.flatnonzero(bad))
    out = ~((q >= limits.q_lower) & (q <= limits.q_upper))
    if out.any():
        return "outside joint limits: " + "; ".join(
            f"{names[int(i)]} = {q[i]:.4f} rad not in [{limits.q_lower[i]:.3f}, {limits.q_upper[i]:.3f}]"
            for i in np.flatnonzero(out)
        )
    max_step = limits.v_max * period
    step = np.abs(q - reference)
    too_far = ~(step <= max_step * (1 + STEP_SLACK) + 1e-12)
    if too_far.any():
        return (
            "step per cycle exceeds v_max * period: "
            + "; ".join(
                f"{names[int(i)]} moves {step[i]:.5f} rad > {max_step[i]:.5f} rad "
                f"({limits.v_max[i]} rad/s x {period * 1000:g} ms)"
                for i in np.flatnonzero(too_far)
            )
            + "; start trajectories at the last setpoint or joint_state().positions"
        )
    return None


@dataclass(frozen=True)
class Rpdo:
    """What one drive's RPDO1 carries this cycle."""

    controlword: int
    #: Target position (rad): always finite and within the joint's limits.
    target: float


@dataclass(frozen=True)
class RpdoPlan:
    """The RPDOs of one cycle, in drive order."""

    #: None for a drive without feedback yet: nothing is sent to it (a target could move the joint).
    frames: tuple[Rpdo | None, ...]
    #: Indices of the drives whose wanted target was refused (the caller latches a fault).
    refused: tuple[int, ...]
    #: Why, naming each refused joint; None if nothing was refused.
    problem: str | None


def plan_rpdos(
    states: Sequence[str | None],
    command: PowerCommand,
    previous: Sequence[int],
    wanted: np.ndarray,
    last_sent: np.ndarray,
    limits: JointLimits,
    names: Sequence[str],
) -> RpdoPlan:
    """Controlword and target of every drive's RPDO for this cycle.

    `states`: each drive's CiA 402 state (None before its first feedback). `previous`: last controlwords.
    `wanted`: the target the cobot means to send (rad): the held setpoint while streaming, otherwise the
    measured position. `last_sent`: the last target sent to each drive (NaN if none). If any wanted
    target is non-finite or outside the limits, every drive gets the quick-stop command (quick stop when
    powered, disable voltage otherwise) and each refused drive the last target it was sent, or failing
    that the limit nearest to the wanted one, or mid-range.
    """
    lo, hi = limits.q_lower, limits.q_upper
    wanted = np.asarray(wanted, dtype=float)
    ok = np.isfinite(wanted) & (wanted >= lo) & (wanted <= hi)  # NaN compares false: refused
    refused = tuple(i for i, state in enumerate(states) if state is not None and not ok[i])
    if refused:
        command = PowerCommand.QUICK_STOP
    frames = tuple(
        None
        if state is None
        else Rpdo(
            controlword_for(state, command, previous[i]),
            float(wanted[i]) if ok[i] else _safe_target(wanted[i], last_sent[i], lo[i], hi[i]),
        )
        for i, state in enumerate(states)
    )
    problem = (
        "; ".join(f"{names[int(i)]} target {wanted[i]:.4f} rad not in [{lo[i]:.3f}, {hi[i]:.3f}]" for i in refused)
        or None
    )
    return RpdoPlan(frames, refused, problem)


def _safe_target(wanted: float, last_sent: float, lo: float, hi: float) -> float:
    """An in-limit target for a drive whose wanted target was refused."""
    if math.isfinite(last_sent) and lo <= last_sent <= hi:
        return float(last_sent)
    if math.isfinite(wanted):
        return float(min(max(wanted, lo), hi))
    return float((lo + hi) / 2)
