"""mrguide: demonstration-augmented DDPG with mixed-reality guidance, a PyBullet twin and a CANopen deploy stack."""

__version__ = "0.2.0"
