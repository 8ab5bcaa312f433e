"""Vacuum generator: part-gripped / part-lost flags follow the vacuum plant."""

from __future__ import annotations

import time


def test_part_gripped_follows_the_plant(rig):
    cobot, sim, plant = rig.cobot, rig.sim, rig.plant
    l1 = rig.config.vacuum.grip_threshold_kpa
    cobot.set_vacuum(True)  # open cup: some vacuum, no part
    assert rig.wait_until(lambda: cobot.vacuum_state().level_kpa > 5.0)
    state = cobot.vacuum_state()
    assert not state.part_gripped and state.level_kpa < l1 and state.vacuum_on

    plant.place_part()  # a part seals the cup
    assert rig.wait_until(lambda: cobot.vacuum_state().part_gripped)
    assert cobot.vacuum_state().level_kpa >= l1 and plant.part_present()

    sim.set_vacuum_leak(0.7)  # the line leaks: level drops below L1 - h1 with the vacuum still on
    assert rig.wait_until(lambda: cobot.vacuum_state().part_lost)
    state = cobot.vacuum_state()
    assert not state.part_gripped and state.level_kpa < l1 - rig.config.vacuum.grip_hysteresis_kpa

    sim.set_vacuum_leak(0.0)
    assert rig.wait_until(lambda: cobot.vacuum_state().part_gripped)
    assert not cobot.vacuum_state().part_lost

    cobot.set_vacuum(False, blow_off=True)  # release
    assert rig.wait_until(lambda: cobot.vacuum_state().level_kpa < 1.0)
    state = cobot.vacuum_state()
    assert not state.part_gripped and not state.part_lost and state.blow_off
    assert not plant.part_present()


def test_vacuum_command_survives_a_drive_fault(rig):
    """A drive fault quick-stops the arm but leaves the vacuum alone: the command is neither cleared nor
    needed again (nothing is re-sent here), the part stays held, and the vacuum RPDO keeps flowing, so a
    release commanded during the fault still reaches the generator."""
    cobot, sim, plant = rig.cobot, rig.sim, rig.plant
    cobot.set_vacuum(True)
    plant.place_part()
    assert rig.wait_until(lambda: cobot.vacuum_state().part_gripped)
    sim.inject_drive_fault(3)
    assert rig.wait_until(lambda: cobot.status().fault is not None)
    assert rig.wait_until(lambda: all(s != "OPERATION ENABLED" for s in cobot.status().drive_states.values()))
    time.sleep(50 * cobot.period)  # the fault has been latched for 50 cycles: still holding
    state = cobot.vacuum_state()
    assert (state.vacuum_on, state.blow_off) == (True, False) and sim.vacuum.commands() == (True, False)
    assert state.part_gripped and state.age < 10 * cobot.period and plant.part_present()
    cobot.set_vacuum(False, blow_off=True)  # accepted during the fault, and sent
    assert rig.wait_until(lambda: sim.vacuum.commands() == (False, True))
    assert rig.wait_until(lambda: not plant.part_present())
