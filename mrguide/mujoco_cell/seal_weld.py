"""The MuJoCo cup's hold on a sealed part: a weld from the seal until the load passes what the seal holds.

Why a weld: MuJoCo's forward dynamics leave out the constraint acceleration's velocity term J̇v for contacts (its
manual, computation: "a velocity-dependent bias for any constraint whose Jacobian varies with configuration ... For
contacts, the term remains omitted"; welds have it). A part held by the cup's adhesion and the lip's friction alone
drifts across the lip as the base turns, ω²-driven and the same for any mass or friction (`tools/slip_probe.py`),
where a real cup does not move. While the seal holds, the weld keeps the part where it sealed, and the lip's
contacts and the adhesion (which would push and pull against the weld) are off: the weld alone carries the part,
so its force is the seal's load.

When the seal lets go: the load is checked against what the vacuum holds (`mrguide.seal`): F = Δp · A, a pull off
the face up to F, a shear along it up to μ (F − pull), a moment about the lip's edge up to (F − pull) · r (the lip's
ring tipping about its edge). Past any of them, or with the vacuum off, the weld is released and the adhesion and
the contacts take over as before: the part tears off, slides or falls as the cell's physics says.
"""

from __future__ import annotations

import mujoco
import numpy as np

from mrguide import seal
from mrguide.cell_layout import CUP_RADIUS
from mrguide.mujoco_cell.model import PA_PER_KPA


class SealWeld:
    """The weld of a MuJoCo cell (`model.build_cell`) between the cup and the part, switched by `update`."""

    def __init__(self, model: mujoco.MjModel, data: mujoco.MjData, cell) -> None:
        self.model, self.data, self.cell = model, data, cell
        self.id = cell.seal_weld
        self._lip_contype = model.geom_contype[cell.lip_geoms].copy()
        self._lip_conaffinity = model.geom_conaffinity[cell.lip_geoms].copy()

    @property
    def active(self) -> bool:
        return bool(self.data.eq_active[self.id])

    def update(self, level_kpa: float, hold_kpa: float, vacuum_on: bool, sealed: bool, touching: bool) -> None:
        """Weld a part the lip rests on (`sealed`: whole, or leaking where it hangs past the face's edge) once the
        level reaches `hold_kpa` (the generator's level that holds a part: the adhesion has drawn it against the lip
        by then); release one whose load the seal no longer holds."""
        holding = level_kpa * PA_PER_KPA * seal.CUP_AREA
        if self.active:
            if not vacuum_on or self._overloaded(holding):
                self._set(False)
        elif vacuum_on and sealed and touching and level_kpa >= hold_kpa:
            self._set(True)

    def release(self) -> None:
        if self.active:
            self._set(False)

    def _set(self, on: bool) -> None:
        m, d, c = self.model, self.data, self.cell
        if on:  # hold the part where it is: the part's origin and orientation in the cup's frame
            x1, x2 = d.xpos[c.cup_body], d.xpos[c.part_body]
            r1 = d.xmat[c.cup_body].reshape(3, 3)
            q1_inv = np.empty(4)
            mujoco.mju_negQuat(q1_inv, d.xquat[c.cup_body])
            rel = np.empty(4)
            mujoco.mju_mulQuat(rel, q1_inv, d.xquat[c.part_body])
            data = m.eq_data[self.id]
            data[0:3] = 0.0  # the anchor: the part's origin
            data[3:6] = r1.T @ (x2 - x1)
            data[6:10] = rel
            data[10] = 1.0  # torquescale
        d.eq_active[self.id] = on
        m.geom_contype[c.lip_geoms] = 0 if on else self._lip_contype
        m.geom_conaffinity[c.lip_geoms] = 0 if on else self._lip_conaffinity

    def load(self) -> tuple[np.ndarray, np.ndarray]:
        """(force, torque) the weld applies to the part, world frame (N, N m); zeros while inactive."""
        d = self.data
        rows = np.flatnonzero(
            (d.efc_type[: d.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY) & (d.efc_id[: d.nefc] == self.id)
        )
        if len(rows) != 6:
            return np.zeros(3), np.zeros(3)
        lam = d.efc_force[rows]
        r2 = d.xmat[self.cell.part_body].reshape(3, 3)
        return -lam[:3], -0.5 * r2 @ lam[3:]

    def _overloaded(self, holding: float) -> bool:
        force, torque = self.load()
        out = self.data.xmat[self.cell.tcp_body].reshape(3, 3)[:, 2]  # the cup's axis, out of the lip
        pull = -float(force @ out)  # what the cup must pull the part toward itself with
        shear = float(np.linalg.norm(force + pull * out))
        moment = float(np.linalg.norm(torque - (torque @ out) * out))
        free = holding - pull
        return free < 0.0 or shear > seal.LIP_FRICTION * free or moment > free * CUP_RADIUS
