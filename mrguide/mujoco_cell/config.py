"""The MuJoCo cell's physical parameters ([plant.mujoco] of a cell config), each with where its value comes from.

None is fitted to a policy or copied from the PyBullet twin's tuning: contact, friction and solver settings are
MuJoCo's own defaults; the rest are the part's material, the cup's geometry and assumptions named as such.
"""

from __future__ import annotations

from dataclasses import dataclass

from mrguide.config import check_number


@dataclass(frozen=True)
class MujocoCellConfig:
    """Physics of the MuJoCo cell."""

    #: Physics step (s). MuJoCo's default is 2 ms; 1 ms divides the 4 ms SYNC period into 4 steps.
    timestep: float = 0.001
    #: Bandwidth of each drive's position loop (Hz), a second-order servo with velocity feed-forward on the
    #: link inertia at home. Assumed: the order of an industrial servo's position loop (10-30 Hz).
    servo_bandwidth_hz: float = 15.0
    servo_damping_ratio: float = 1.0
    #: The part: a solid 5 cm cube of ABS (density 1.04 g/cm³ → 0.13 kg).
    part_mass: float = 0.13
    #: How far the cup's lip may stand off the part's top face and still seal (m): the lip's compliance.
    #: Assumed (a flat cup's lip deforms by about a millimetre).
    seal_gap: float = 0.001

    def __post_init__(self) -> None:
        check_number("plant.mujoco.timestep", self.timestep, 1e-5, 0.01, " s")
        check_number("plant.mujoco.servo_bandwidth_hz", self.servo_bandwidth_hz, 0.5, 200.0, " Hz")
        check_number("plant.mujoco.servo_damping_ratio", self.servo_damping_ratio, 0.1, 5.0)
        check_number("plant.mujoco.part_mass", self.part_mass, 1e-3, 10.0, " kg")
        check_number("plant.mujoco.seal_gap", self.seal_gap, 0.0, 0.01, " m")
