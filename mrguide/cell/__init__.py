"""The dry-run harness of the deploy stack: simulated cells (the PyBullet twin with reality-gap parameters, or the
MuJoCo cell) behind simulated CANopen devices, in a process of their own, and the camera and HMD renderers that
stand in for a real cell's pose sources. Above both `deploy` (whose runtime it drives) and `twin` (whose scene can
be its plant); the training simulator itself stays in `twin`."""
