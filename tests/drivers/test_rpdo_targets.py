"""No out-of-limit target reaches the bus, whatever the path: enable, quick stop, fault reset, disable.

A drive whose position feedback goes wrong (+100 rad, as a slipped encoder or a wrong offset would report)
must not get that position back as its target: the RPDO frames actually seen on the virtual bus are
decoded and every target checked against the joint limits, and the simulated joint must stay inside them.
"""

from __future__ import annotations

import contextlib
import struct
import time

import numpy as np
import pytest
from canopen.profiles.p402 import State402

from mrguide.drivers import DeviceFaultError, DriverError
from mrguide.drivers.cia402 import PowerCommand, controlword_for
from mrguide.drivers.config import JointLimits
from mrguide.drivers.conversion import JointConversion
from mrguide.drivers.mock.drive_sim import OPERATION_ENABLED, QUICK_STOP_ACTIVE, SWITCH_ON_DISABLED, SWITCHED_ON
from mrguide.drivers.setpoint_guard import plan_rpdos

NODE, JOINT = 6, 3  # wrist_1_joint: limits -3.8 .. 0.6 rad
WRONG_BY = 100.0  # rad added to the position the drive reports
#: Half a count of rounding plus float slack, in rad.
COUNT_SLACK = 1e-5


def _rpdos(tap, config, node_id: int) -> list[tuple[int, float]]:
    """(controlword, target in rad) of every RPDO1 the master sent to `node_id`."""
    joint = next(j for j in config.joints if j.node_id == node_id)
    conv = JointConversion.from_config(joint)
    return [
        (cw, conv.to_rad(counts))
        for cw, counts in (struct.unpack_from("<Hi", bytes(m.data)) for m in tap.with_id(0x200 + node_id))
    ]


def _assert_all_targets_within_limits(tap, rig) -> None:
    lim = rig.cobot.limits
    for i, joint in enumerate(rig.config.joints):
        frames = _rpdos(tap, rig.config, joint.node_id)
        bad = [
            (hex(cw), round(t, 3))
            for cw, t in frames
            if not lim.q_lower[i] - COUNT_SLACK <= t <= lim.q_upper[i] + COUNT_SLACK
        ]
        assert not bad, f"{len(bad)} of {len(frames)} RPDOs to node {joint.node_id} outside the limits: {bad[:5]}"
    q = rig.plant.joint_positions()
    assert np.all(q >= lim.q_lower - 1e-3) and np.all(q <= lim.q_upper + 1e-3), f"simulated joints moved to {q}"


def _wrong_feedback_while_enabling(rig) -> None:
    """The drive's feedback goes wrong as soon as it leaves SWITCH ON DISABLED (in the simulator's SYNC thread)."""
    drive = next(d for d in rig.sim.drives if d.node_id == NODE)
    cycle = drive.cycle

    def cycle_then_fail(q: float, v: float, dt: float) -> float:
        target = cycle(q, v, dt)
        if drive.state != SWITCH_ON_DISABLED:
            rig.sim.faults.set_position_error(NODE, WRONG_BY)
        return target

    drive.cycle = cycle_then_fail
    with contextlib.suppress(DriverError):
        rig.cobot.enable()


def _wrong_feedback_then_quick_stop(rig) -> None:
    rig.cobot.enable()
    rig.sim.faults.set_position_error(NODE, WRONG_BY)
    rig.cobot.stop()


def _wrong_feedback_then_fault_reset(rig) -> None:
    rig.cobot.enable()
    rig.sim.inject_drive_fault(NODE)
    assert rig.wait_until(lambda: rig.cobot.status().fault is not None)
    rig.sim.faults.set_position_error(NODE, WRONG_BY)
    with contextlib.suppress(DriverError):
        rig.cobot.reset_faults(timeout=0.3)
    with pytest.raises(DriverError):  # no recovery into enable with a wrong position
        rig.cobot.enable(timeout=0.3)


def _wrong_feedback_while_disabled(rig) -> None:
    rig.sim.faults.set_position_error(NODE, WRONG_BY)


PATHS = {
    "enable": _wrong_feedback_while_enabling,
    "quick_stop": _wrong_feedback_then_quick_stop,
    "fault_reset": _wrong_feedback_then_fault_reset,
    "disable": _wrong_feedback_while_disabled,
}


@pytest.mark.parametrize("path", sorted(PATHS))
def test_wrong_position_feedback_never_becomes_an_out_of_limit_target(make_rig, tap_on, path):
    rig = make_rig()
    tap = tap_on(rig.config.bus.channel)
    PATHS[path](rig)
    sent = len(tap.with_id(0x200 + NODE))
    assert rig.wait_until(lambda: len(tap.with_id(0x200 + NODE)) >= sent + 20), "RPDOs stopped"
    rig.cobot.disconnect()
    time.sleep(0.05)  # the last frames reach the tap
    _assert_all_targets_within_limits(tap, rig)
    fault = rig.cobot.status().fault
    assert isinstance(fault, DeviceFaultError) and fault.node_id == NODE, fault


# ---------------------------------------------------------------- the pure function deciding every RPDO

NAMES = tuple(f"j{i}" for i in range(6))
STATES = (OPERATION_ENABLED,) * 3 + (SWITCHED_ON, QUICK_STOP_ACTIVE, SWITCH_ON_DISABLED)
NON_ENABLING = (State402.CW_QUICK_STOP, State402.CW_DISABLE_VOLTAGE)


@pytest.fixture(scope="module")
def limits(robot):
    return JointLimits(robot.q_lower, robot.q_upper, robot.v_max)


def test_targets_within_limits_go_out_as_wanted(limits, robot):
    wanted = robot.q_home + 0.01
    plan = plan_rpdos(STATES, PowerCommand.ENABLE, [0] * 6, wanted, np.full(6, np.nan), limits, NAMES)
    assert plan.refused == () and plan.problem is None
    assert [f.target for f in plan.frames] == pytest.approx(wanted)
    assert [f.controlword for f in plan.frames] == [controlword_for(s, PowerCommand.ENABLE, 0) for s in STATES]


@pytest.mark.parametrize("bad", [100.0, -100.0, np.nan, np.inf, -np.inf])
@pytest.mark.parametrize("command", list(PowerCommand))
def test_a_bad_target_is_refused_and_no_drive_gets_an_enabling_controlword(limits, robot, bad, command):
    wanted = robot.q_home.copy()
    wanted[3] = bad
    last = np.full(6, np.nan)
    plan = plan_rpdos(STATES, command, [0] * 6, wanted, last, limits, NAMES)
    assert plan.refused == (3,) and "j3" in plan.problem
    assert all(f.controlword in NON_ENABLING for f in plan.frames)
    targets = np.array([f.target for f in plan.frames])
    assert np.all(np.isfinite(targets)) and np.all(targets >= limits.q_lower) and np.all(targets <= limits.q_upper)
    last[3] = -1.0  # with a target sent before, the refused drive gets that one again
    assert plan_rpdos(STATES, command, [0] * 6, wanted, last, limits, NAMES).frames[3].target == -1.0


def test_no_frame_for_a_drive_without_feedback(limits, robot):
    wanted = robot.q_home.copy()
    wanted[0] = np.nan  # no measured position yet
    plan = plan_rpdos((None, *STATES[1:]), PowerCommand.DISABLE, [0] * 6, wanted, np.full(6, np.nan), limits, NAMES)
    assert plan.frames[0] is None and plan.refused == ()


def test_no_random_input_gets_a_bad_target_out(limits):
    rng = np.random.default_rng(13)
    specials = np.array([np.nan, np.inf, -np.inf, 1e300, -1e300, 0.0])
    for _ in range(2000):
        wanted = rng.uniform(-10, 10, 6)
        wanted[rng.random(6) < 0.2] = rng.choice(specials)
        last = np.where(rng.random(6) < 0.5, rng.uniform(limits.q_lower, limits.q_upper), np.nan)
        states = [rng.choice([*STATES, None]) for _ in range(6)]
        plan = plan_rpdos(states, rng.choice(list(PowerCommand)), [0] * 6, wanted, last, limits, NAMES)
        for i, frame in enumerate(plan.frames):
            if frame is None:
                continue
            assert limits.q_lower[i] <= frame.target <= limits.q_upper[i]
            if plan.refused:
                assert frame.controlword in NON_ENABLING
