"""`Cobot` implements `CobotInterface`, the protocol the deploy runtime relies on."""

from __future__ import annotations

import inspect

from mrguide.drivers import Cobot, CobotInterface

MEMBERS = (
    "period",
    "setpoint_queue_depth",
    "feedback_tolerance_cycles",
    "setpoint",
    "enable",
    "stream",
    "set_vacuum",
    "stop",
    "reset_faults",
    "joint_state",
    "vacuum_state",
    "stats",
    "add_cycle_observer",
    "remove_cycle_observer",
)


def test_the_protocol_is_what_the_runtime_uses():
    declared = {name for name in dir(CobotInterface) if not name.startswith("_")} | set(CobotInterface.__annotations__)
    assert declared == set(MEMBERS)


def test_a_connected_cobot_is_a_cobot_interface(rig):
    assert isinstance(rig.cobot, CobotInterface)
    assert rig.cobot.setpoint_queue_depth == rig.config.timing.setpoint_queue_depth
    assert rig.cobot.feedback_tolerance_cycles == rig.config.timing.max_missed_feedback


def test_cobot_methods_take_the_protocols_parameters():
    for name in MEMBERS:
        spec = getattr(CobotInterface, name, None)
        if callable(spec):
            assert list(inspect.signature(getattr(Cobot, name)).parameters) == list(
                inspect.signature(spec).parameters
            ), name
