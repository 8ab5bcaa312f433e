"""The cell on a second, independently written physics engine: MuJoCo behind the simulated CANopen drives.

Nothing on the robot side imports this package (the `mujoco` extra); the driver layer sees only its `Plant`.
"""
