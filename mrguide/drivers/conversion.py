"""Joint radians <-> drive encoder counts, shared by the master and the simulated drives."""

from __future__ import annotations

import math
from dataclasses import dataclass

from mrguide.drivers.config import JointDriveConfig


@dataclass(frozen=True)
class JointConversion:
    """counts = direction * (q - offset) * counts_per_rad, counts_per_rad = resolution * gear / 2pi."""

    counts_per_rad: float
    offset: float = 0.0
    direction: int = 1

    @classmethod
    def from_config(cls, joint: JointDriveConfig) -> JointConversion:
        return cls(joint.encoder_resolution * joint.gear_ratio / (2 * math.pi), joint.offset, joint.direction)

    def to_counts(self, q: float) -> int:
        """Joint angle (rad) to position counts."""
        return round(self.direction * (q - self.offset) * self.counts_per_rad)

    def to_rad(self, counts: int) -> float:
        """Position counts to joint angle (rad)."""
        return self.direction * counts / self.counts_per_rad + self.offset

    def velocity_to_counts(self, v: float) -> int:
        """Joint velocity (rad/s) to counts/s."""
        return round(self.direction * v * self.counts_per_rad)

    def velocity_to_rad(self, counts_per_s: int) -> float:
        """Counts/s to joint velocity (rad/s)."""
        return self.direction * counts_per_s / self.counts_per_rad

    def magnitude_to_counts(self, x: float) -> int:
        """A direction-free magnitude (window, deceleration) in rad-based units to counts-based units."""
        return round(abs(x) * self.counts_per_rad)
