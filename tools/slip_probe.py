"""How far a held part drifts across the cup's lip in a scripted transport, with MuJoCo's default contact time
constant and with the MuJoCo cell's (the evidence for `model.CONTACT_TIMECONST_STEPS`).

    python tools/slip_probe.py

The cup seals on a part at (0.50, -0.10), lifts it 12.5 cm and carries it to (0.45, 0.25) on a jerk-limited joint
trajectory at the arm's limits; printed: the part's displacement in the TCP frame over the transport (mm) and
whether the seal held to the end. No bus: the plant is stepped directly, one control period at a time.
"""

from __future__ import annotations

import numpy as np

from mrguide.motion.kinematics import Kinematics
from mrguide.motion.trajectory import point_to_point
from mrguide.mujoco_cell.config import MujocoCellConfig
from mrguide.mujoco_cell.model import CONTACT_TIMECONST_STEPS
from mrguide.mujoco_cell.plant import MujocoPlant
from mrguide.robot import load_robot

PART, PLACE = np.array([0.50, -0.10, 0.025]), np.array([0.45, 0.25, 0.15])
PERIOD = 0.004  # s, the bus's SYNC period
MUJOCO_DEFAULT_TIMECONST = 0.02  # s, MuJoCo's default solref


def drift(timeconst: float) -> tuple[np.ndarray, bool]:
    """(the part's displacement in the TCP frame over the transport in mm, whether the seal held throughout)."""
    spec = load_robot()
    kin, plant = Kinematics(spec), MujocoPlant(spec)
    plant.model.geom_solref[:] = (timeconst, 1.0)
    plant.place_objects(PART, PART + [0.0, 0.2, 0.0])
    held = [True]

    def in_tcp() -> np.ndarray:
        d, c = plant.data, plant.cell
        return 1e3 * d.xmat[c.tcp_body].reshape(3, 3).T @ (d.xpos[c.part_body] - d.xpos[c.tcp_body])

    def move(target: np.ndarray, hold: int = 50, watch: bool = False) -> None:
        q_to = kin.ik(target, plant.joint_positions())
        for q in [*point_to_point(spec, plant.joint_positions(), q_to, PERIOD), *[q_to] * hold]:
            plant.set_joint_targets(q)
            plant.step(PERIOD)
            held[0] = held[0] and (not watch or plant.lip_sealed())

    move(PART + [0.0, 0.0, 0.08])
    move(PART + [0.0, 0.0, 0.025])
    plant.set_vacuum(True, False)
    move(PART + [0.0, 0.0, 0.15])
    start = in_tcp()
    move(PLACE, hold=20, watch=True)
    return in_tcp() - start, held[0]


def main() -> None:
    for label, timeconst in (
        ("MuJoCo's default", MUJOCO_DEFAULT_TIMECONST),
        ("the MuJoCo cell's", CONTACT_TIMECONST_STEPS * MujocoCellConfig().timestep),
    ):
        moved, held = drift(timeconst)
        print(
            f"{label} contact time constant {timeconst * 1e3:.0f} ms: the part moved {np.round(moved, 2).tolist()} mm "
            f"in the TCP frame ({np.linalg.norm(moved[:2]):.1f} mm across the lip); seal held: {held}"
        )


if __name__ == "__main__":
    main()
