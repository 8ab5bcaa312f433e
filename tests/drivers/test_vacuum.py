"""Vacuum generator: part-gripped / part-lost flags follow the vacuum plant."""

from __future__ import annotations

def test_part_gripped_follows_the_plant(rig):
    cobot, sim, plant = rig.cobot, rig.sim, rig.plant
    l1 = rig.config.vacuum.grip_threshold_kpa
    cobot.set_vacuum(True)  # open cup: some vacuum, no part
    assert rig.wait_until(lambda: cobot.vacuum_state().level_kpa > 5.0)
    state = cobot.vacuum_state()
    assert not state.part_gripped and state.level_kpa < l1 and state.vacuum_on

    plant.place_part()  # a part seals the cup
    assert rig.wait_until(lambda: cobot.vacuum_state().part_gripped, timeout=0.5)
    assert cobot.vacuum_state().level_kpa >= l1 and plant.part_present()

    sim.set_vacuum_leak(0.7)  # the line leaks: level drops below L1 - h1 with the vacuum still on
    assert rig.wait_until(lambda: cobot.vacuum_state().part_lost, timeout=0.5)
    state = cobot.vacuum_state()
    assert not state.part_gripped and state.level_kpa < l1 - rig.config.vacuum.grip_hysteresis_kpa

    sim.set_vacuum_leak(0.0)
    assert rig.wait_until(lambda: cobot.vacuum_state().part_gripped, timeout=0.5)
    assert not cobot.vacuum_state().part_lost

    cobot.set_vacuum(False, blow_off=True)  # release
    assert rig.wait_until(lambda: cobot.vacuum_state().level_kpa < 1.0, timeout=0.5)
    state = cobot.vacuum_state()
    assert not state.part_gripped and not state.part_lost and state.blow_off
    assert not plant.part_present()


def test_vacuum_command_survives_a_drive_fault(rig):
    rig.cobot.set_vacuum(True)
    rig.plant.place_part()
    assert rig.wait_until(lambda: rig.cobot.vacuum_state().part_gripped, timeout=0.5)
    rig.sim.inject_drive_fault(3)
    assert rig.wait_until(lambda: rig.cobot.status().fault is not None)
    rig.cobot.set_vacuum(True)  # still accepted: a held part must stay held
    assert rig.cobot.vacuum_state().part_gripped and rig.plant.part_present()
