"""Motion: Pinocchio kinematics and Ruckig trajectories, shared by the twin, the deploy runtime and the drivers' self-test."""
