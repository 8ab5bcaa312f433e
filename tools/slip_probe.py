"""How far a held part drifts across the cup's lip in a scripted transport when the lip's contacts and the adhesion
alone hold it, with MuJoCo's default contact time constant and with the MuJoCo cell's (the evidence for
`model.CONTACT_TIMECONST_STEPS`); which motion makes it drift and what of MuJoCo's options changes it; and the same
with the cell's seal weld (`mujoco_cell.seal_weld`, the evidence for it).

    python tools/slip_probe.py

The cup seals on a part at (0.50, -0.10), lifts it 12.5 cm and carries it to (0.45, 0.25) on a jerk-limited joint
trajectory at the arm's limits; printed: the part's displacement in the TCP frame over the transport (mm) and
whether the seal held to the end. Then, from the same lifted grasp, single moves: the base joint or the wrist
turned 0.8 rad, a 10 cm straight move; the base's turn at half speed, with a heavy part, and with MuJoCo's
no-slip pass, harder contact impedance or half the contact time constant. No bus: the
plant is stepped directly, one control period at a time.
"""

from __future__ import annotations

from collections.abc import Callable

import mujoco
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
TURN = 0.8  # rad, the single joint moves


class HeldPart:
    """The MuJoCo cell with the part sealed and lifted 12.5 cm, moved by joint trajectories."""

    def __init__(self, timeconst: float, part_mass: float | None = None, weld: bool = False):
        self.spec = load_robot()
        cfg = MujocoCellConfig() if part_mass is None else MujocoCellConfig(part_mass=part_mass)
        self.kin, self.plant = Kinematics(self.spec), MujocoPlant(self.spec, cfg)
        if not weld:  # the lip's contacts and the adhesion alone, as the cell held a part before its weld
            self.plant.weld.update = lambda *args: None  # type: ignore[method-assign]
        self.plant.model.geom_solref[:] = (timeconst, 1.0)
        self.plant.place_objects(PART, PART + [0.0, 0.2, 0.0])
        self.held = True
        self.move_to(PART + [0.0, 0.0, 0.08])
        self.move_to(PART + [0.0, 0.0, 0.025])
        self.plant.set_vacuum(True, False)
        self.move_to(PART + [0.0, 0.0, 0.15])

    def in_tcp(self) -> np.ndarray:
        """The part's position in the TCP frame (mm)."""
        d, c = self.plant.data, self.plant.cell
        return 1e3 * d.xmat[c.tcp_body].reshape(3, 3).T @ (d.xpos[c.part_body] - d.xpos[c.tcp_body])

    def move_to(self, target: np.ndarray, hold: int = 50, watch: bool = False) -> None:
        self.move_joints(self.kin.ik(target, self.plant.joint_positions()), hold=hold, watch=watch)

    def move_joints(self, q_to: np.ndarray, hold: int = 50, watch: bool = False, slower: int = 1) -> None:
        """A jerk-limited move to `q_to`, `slower` times as long (the same path), then `hold` periods at rest."""
        path = np.array(point_to_point(self.spec, self.plant.joint_positions(), q_to, PERIOD))
        t = np.linspace(0.0, len(path) - 1, (len(path) - 1) * slower + 1)
        path = np.array([np.interp(t, np.arange(len(path)), path[:, j]) for j in range(path.shape[1])]).T
        for q in [*path, *[q_to] * hold]:
            self.plant.set_joint_targets(q)
            self.plant.step(PERIOD)
            self.held = self.held and (not watch or self.plant.lip_sealed())


def drift(timeconst: float, weld: bool = False) -> tuple[np.ndarray, bool]:
    """(the part's displacement in the TCP frame over the transport in mm, whether the seal held throughout)."""
    cell = HeldPart(timeconst, weld=weld)
    start = cell.in_tcp()
    cell.move_to(PLACE, hold=20, watch=True)
    return cell.in_tcp() - start, cell.held


def _no_slip(model: mujoco.MjModel) -> None:
    model.opt.noslip_iterations = 50


def _hard_impedance(model: mujoco.MjModel) -> None:
    model.geom_solimp[:, :2] = (0.999, 0.9999)


def _half_time_constant(model: mujoco.MjModel) -> None:
    model.geom_solref[:, 0] *= 0.5


def drift_per_motion(timeconst: float) -> dict[str, float]:
    """The part's drift across the lip (mm) for each single move from the lifted grasp."""

    def turn(joint: int, angle: float = TURN) -> Callable[[HeldPart], np.ndarray]:
        return lambda cell: cell.plant.joint_positions() + angle * np.eye(cell.spec.dof)[joint]

    def straight(cell: HeldPart) -> np.ndarray:
        return cell.kin.ik(PART + [0.10, 0.0, 0.15], cell.plant.joint_positions())

    def keep(model: mujoco.MjModel) -> None:
        pass

    base = f"base joint turned {TURN} rad"
    moves: dict[str, tuple[Callable[[HeldPart], np.ndarray], int, Callable[[mujoco.MjModel], None], float | None]] = {
        base: (turn(0), 1, keep, None),
        f"{base} the other way": (turn(0, -TURN), 1, keep, None),
        f"wrist turned {TURN} rad about the cup's axis": (turn(5), 1, keep, None),
        "a 10 cm straight move": (straight, 1, keep, None),
        f"{base}, half speed": (turn(0), 2, keep, None),
        f"{base}, a 1.3 kg part": (turn(0), 1, keep, 1.3),
        f"{base}, 50 no-slip iterations": (turn(0), 1, _no_slip, None),
        f"{base}, contact impedance 0.999-0.9999": (turn(0), 1, _hard_impedance, None),
        f"{base}, half the contact time constant": (turn(0), 1, _half_time_constant, None),
    }
    out = {}
    for label, (target, slower, tweak, mass) in moves.items():
        cell = HeldPart(timeconst, mass)
        tweak(cell.plant.model)
        start = cell.in_tcp()
        cell.move_joints(target(cell), hold=20, slower=slower)
        out[label] = float(np.linalg.norm((cell.in_tcp() - start)[:2]))
    return out


def main() -> None:
    cells = CONTACT_TIMECONST_STEPS * MujocoCellConfig().timestep
    for label, timeconst, weld in (
        ("the contacts alone, MuJoCo's default", MUJOCO_DEFAULT_TIMECONST, False),
        ("the contacts alone, the MuJoCo cell's", cells, False),
        ("the MuJoCo cell (its seal's weld), its", cells, True),
    ):
        moved, held = drift(timeconst, weld)
        print(
            f"{label} contact time constant {timeconst * 1e3:.0f} ms: the part moved {np.round(moved, 2).tolist()} mm "
            f"in the TCP frame ({np.linalg.norm(moved[:2]):.1f} mm across the lip); seal held: {held}"
        )
    for label, across in drift_per_motion(cells).items():
        print(f"the cell's contacts alone, {label}: {across:.2f} mm across the lip")
    cell = HeldPart(cells, weld=True)
    start = cell.in_tcp()
    cell.move_joints(cell.plant.joint_positions() + TURN * np.eye(cell.spec.dof)[0], hold=20)
    print(
        f"the MuJoCo cell (its seal's weld), base joint turned {TURN} rad: "
        f"{np.linalg.norm((cell.in_tcp() - start)[:2]):.2f} mm across the lip"
    )


if __name__ == "__main__":
    main()
