"""Setpoint validation: refused before anything is queued or sent."""

from __future__ import annotations

import struct
import time

import numpy as np
import pytest

from mrguide.drivers import NotReadyError, SetpointError
from mrguide.drivers.conversion import JointConversion


def _targets(tap, node_id):
    """Target positions (counts) in the RPDO1 frames sent to a drive."""
    return {struct.unpack_from("<Hi", bytes(m.data))[1] for m in tap.with_id(0x200 + node_id)}


@pytest.mark.parametrize(
    "make_bad, words",
    [
        (lambda q, lim: q + np.r_[0.0, 0.0, 1.0, 0, 0, 0], ["step per cycle", "elbow_joint"]),
        (lambda q, lim: np.where(np.arange(6) == 3, lim.q_upper + 0.01, q), ["outside joint limits", "wrist_1_joint"]),
        (lambda q, lim: np.where(np.arange(6) == 0, np.nan, q), ["non-finite", "shoulder_pan_joint"]),
        (lambda q, lim: np.where(np.arange(6) == 5, np.inf, q), ["non-finite", "wrist_3_joint"]),
        (lambda q, lim: q[:5], ["shape"]),
        (lambda q, lim: ["a"] * 6, ["not an array"]),
        # a complex setpoint, even with a zero imaginary part: np.array(dtype=float) would drop it silently
        (lambda q, lim: q + 0j, ["real numbers", "complex128"]),
        (lambda q, lim: list(q[:5]) + [complex(q[5], 1e-3)], ["real numbers", "complex128"]),
        (lambda q, lim: np.zeros(6, dtype=bool), ["real numbers", "bool"]),
        (lambda q, lim: list(q[:5]) + [None], ["real numbers", "object"]),
    ],
)
def test_bad_setpoint_is_refused_and_never_sent(rig, tap_on, make_bad, words):
    cobot = rig.cobot
    tap = tap_on(rig.config.bus.channel)
    hold = cobot.setpoint
    hold_counts = {JointConversion.from_config(rig.config.joints[0]).to_counts(hold[0])}
    time.sleep(0.02)
    with pytest.raises(SetpointError) as info:
        cobot.stream(make_bad(hold, cobot.limits))
    for word in words:
        assert word in str(info.value)
    sent = len(tap.with_id(0x203))
    assert rig.wait_until(lambda: len(tap.with_id(0x203)) >= sent + 12)  # a dozen more cycles
    assert _targets(tap, 3) == hold_counts  # drive 3 only ever got the held position
    np.testing.assert_array_equal(cobot.setpoint, hold)
    assert cobot.stats().refused_setpoints == 1
    assert cobot.status().fault is None
    cobot.stream(hold + 0.001)  # a good setpoint is still accepted afterwards


def test_last_setpoint_is_the_reference_for_the_step_check(rig):
    cobot = rig.cobot
    q = cobot.setpoint
    max_step = cobot.limits.v_max * cobot.period
    cobot.stream(q + 0.99 * max_step)
    cobot.stream(q + 1.98 * max_step)  # one more step from the queued setpoint, not from the robot
    with pytest.raises(SetpointError, match="step per cycle"):
        cobot.stream(q)  # two steps back at once


def test_streaming_needs_enable_and_vacuum_commands_are_checked(make_rig, robot):
    rig = make_rig()
    with pytest.raises(NotReadyError, match="enable"):
        rig.cobot.stream(robot.q_home)
    with pytest.raises(SetpointError, match="same time"):
        rig.cobot.set_vacuum(True, blow_off=True)
    with pytest.raises(SetpointError, match="booleans"):
        rig.cobot.set_vacuum(1)
    assert rig.cobot.vacuum_state().vacuum_on is False
