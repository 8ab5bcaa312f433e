"""A simulated vacuum generator with LEMCOM-like manufacturer objects (the slave side).

Per SYNC: the valve command (0x2000) goes to the plant; the plant's vacuum level becomes 0x2020:01;
"part gripped" (0x2001) rises above threshold L1 and falls below L1 - h1 (hysteresis); "part lost"
(0x2003) is set when, with vacuum on, a gripped part's level falls below L1 - h1, and cleared when
the vacuum is switched off or the part is gripped again.
"""

from __future__ import annotations

from mrguide.drivers import objects
from mrguide.drivers.mock.slave import SimulatedSlave
from mrguide.drivers.objects import (
    GRIP_HYSTERESIS,
    GRIP_THRESHOLD,
    PART_GRIPPED,
    PART_LOST,
    VACUUM_COMMAND,
    VACUUM_LEVEL,
)
from mrguide.drivers.vacuum import BLOW_OFF_BIT, LEVEL_UNIT_KPA, MODULE0_BIT, VACUUM_ON_BIT

COMMAND = (VACUUM_COMMAND, 0)
GRIPPED = (PART_GRIPPED, 0)
LOST = (PART_LOST, 0)
LEVEL = (VACUUM_LEVEL, 1)
THRESHOLD = (GRIP_THRESHOLD, 0)
HYSTERESIS = (GRIP_HYSTERESIS, 0)
ERROR_REGISTER = (objects.ERROR_REGISTER, 0)


class SimulatedVacuumGenerator(SimulatedSlave):
    """Vacuum generator, module 0 of a LEMCOM-style island."""

    def reset_application(self) -> None:
        self.image = {COMMAND: 0, GRIPPED: 0, LOST: 0, LEVEL: 0, ERROR_REGISTER: 0}
        self._gripped = False
        self._was_gripped = False
        self._reload_thresholds()

    def _reload_thresholds(self) -> None:
        self._threshold = self.value(THRESHOLD) * LEVEL_UNIT_KPA
        self._release = self._threshold - self.value(HYSTERESIS) * LEVEL_UNIT_KPA

    def after_write(self, index: int, subindex: int) -> None:
        if (index, subindex) in (THRESHOLD, HYSTERESIS):
            self._reload_thresholds()

    def commands(self) -> tuple[bool, bool]:
        """(vacuum on, blow-off) for module 0."""
        bits = self.image[COMMAND]
        return bool(bits & VACUUM_ON_BIT), bool(bits & BLOW_OFF_BIT)

    def cycle(self, level_kpa: float) -> None:
        """Update the level and the gripped/lost signals from the plant's vacuum level."""
        vacuum_on, _ = self.commands()
        if level_kpa >= self._threshold:
            self._gripped = True
        elif level_kpa < self._release:
            self._gripped = False
        self._was_gripped = vacuum_on and (self._was_gripped or self._gripped)
        lost = self._was_gripped and not self._gripped
        self.image[LEVEL] = min(max(round(level_kpa / LEVEL_UNIT_KPA), 0), 0xFFFF)
        self.image[GRIPPED] = MODULE0_BIT if self._gripped else 0
        self.image[LOST] = MODULE0_BIT if lost else 0
