"""What the cell's render processes (the camera feed, the HMD stream) share: their priority, how one is stopped, what
MuJoCo's offscreen renderer needs, and the marked part a PyBullet render process draws."""

from __future__ import annotations

import contextlib

import pybullet as pb

from mrguide.cell_layout import TABLE_CENTER, TABLE_HALF_EXTENTS
from mrguide.twin.markers import MarkerOnBody, marker_on_cube_top

#: The render process yields the CPU to the control loop (it uses a core of its own while it renders).
RENDER_NICENESS = 10
#: What MuJoCo's offscreen renderer needs, for the errors that say it is missing.
OFFSCREEN_GL_HELP = (
    "MuJoCo's offscreen renderer needs EGL (Debian: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri; "
    "MUJOCO_GL=egl, the default here) or OSMesa (apt-get install libosmesa6; MUJOCO_GL=osmesa), set before mujoco "
    "is imported"
)


def stop_render_process(conn, proc) -> None:
    """Ask a render process to end (None on its pipe), wait 5 s, then kill it."""
    with contextlib.suppress(BrokenPipeError, OSError):
        conn.send(None)
    proc.join(timeout=5)
    if proc.is_alive():
        proc.kill()


def marked_object_scene(
    client: int, object_size: float, dictionary: str, marker_id: int, marker_size_m: float
) -> tuple[int, MarkerOnBody]:
    """A visual-only table and cube with the object marker on its top face (5 mm quiet zone); (cube, marker)."""
    vis = pb.createVisualShape(
        pb.GEOM_BOX, halfExtents=TABLE_HALF_EXTENTS, rgbaColor=(0.75, 0.72, 0.66, 1), physicsClientId=client
    )
    pb.createMultiBody(0, -1, vis, TABLE_CENTER, physicsClientId=client)
    h = object_size / 2
    cube_vis = pb.createVisualShape(
        pb.GEOM_BOX, halfExtents=(h, h, h), rgbaColor=(0.85, 0.1, 0.1, 1), physicsClientId=client
    )
    cube = pb.createMultiBody(0, -1, cube_vis, (0.5, -0.1, h), physicsClientId=client)
    marker = MarkerOnBody(
        client, cube, marker_on_cube_top(object_size), dictionary, marker_id, marker_size_m, quiet_zone_m=0.005
    )
    return cube, marker
