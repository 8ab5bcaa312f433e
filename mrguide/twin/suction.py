"""Vacuum gripper of the twin: a fixed constraint made on contact, broken by force, plus a vacuum signal.

As in google-research/ravens, suction is a fixed constraint between the cup and the object, created when
the vacuum is on and the cup lip sits on the object's top face, removed on release. Unlike ravens, the
constraint breaks when its force exceeds the break force, and the generator reports a vacuum level that
responds with a first-order lag, from which the part-present signal is derived as on a real unit.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import pybullet as pb

from mrguide.twin.config import VacuumConfig


@dataclass
class SuctionState:
    """Everything needed to restore the cup: vacuum command, level, and the attachment (if any)."""

    vacuum_on: bool = False
    level: float = 0.0
    attached: bool = False
    rel_pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rel_orn: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    breaks: int = 0


class SuctionCup:
    """The vacuum cup on link `cup_link` of `robot`, gripping the cube `obj` of edge `obj_size`."""

    def __init__(self, client: int, robot: int, cup_link: int, obj: int, obj_size: float, cfg: VacuumConfig, dt: float):
        self.client, self.robot, self.cup_link, self.obj = client, robot, cup_link, obj
        self.half = 0.5 * obj_size
        self.cfg = cfg
        self.dt = dt
        self._level_gain = 1.0 - math.exp(-dt / cfg.time_constant)  # first-order lag over one period
        self.break_force = math.inf
        self.leak = 0.0  # fault injection: fraction of the sealed vacuum lost through a leak
        #: Called at each break with the constraint's force (N, in the cup frame) and the cup's pose in the part's
        #: frame (position, m): for probes (tools/break_probe.py).
        self.on_break: Callable[[tuple[float, ...], tuple[float, ...]], None] | None = None
        self.state = SuctionState()
        self._cid: int | None = None

    def set_vacuum(self, on: bool) -> None:
        """Vacuum on (grip) or off (release: the constraint goes at once)."""
        self.state.vacuum_on = bool(on)
        if not on:
            self._detach()

    def part_present(self, level: float | None = None) -> bool:
        """The generator's part-gripped signal: level below the threshold."""
        return (self.state.level if level is None else level) < self.cfg.part_threshold

    def update(self) -> None:
        """One physics period: seal if possible, break if overloaded, advance the vacuum level."""
        s = self.state
        if s.vacuum_on and not s.attached and self._sealed():
            self._attach()
        elif s.attached and self._cid is not None:
            fx, fy, fz = pb.getConstraintState(self._cid, physicsClientId=self.client)[:3]
            if math.hypot(fx, fy, fz) > self.break_force:
                s.breaks += 1
                if self.on_break is not None:
                    self.on_break((fx, fy, fz), tuple(self._tcp_in_object()[0]))
                self._detach()
        target = 0.0
        if s.vacuum_on:
            target = (self.cfg.level_sealed * (1.0 - self.leak)) if s.attached else self.cfg.level_open
        s.level += (target - s.level) * self._level_gain
        if s.attached and target > self.cfg.part_threshold and s.level > self.cfg.part_threshold:
            self._detach()  # a leak let the vacuum decay below what holds the part: it falls

    def _tcp_in_object(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Cup pose in the object frame (position, quaternion x y z w); called every period while the vacuum is on."""
        tcp_pos, tcp_orn = pb.getLinkState(
            self.robot, self.cup_link, computeForwardKinematics=True, physicsClientId=self.client
        )[4:6]
        obj_pos, obj_orn = pb.getBasePositionAndOrientation(self.obj, physicsClientId=self.client)
        inv_pos, inv_orn = pb.invertTransform(obj_pos, obj_orn)
        return pb.multiplyTransforms(inv_pos, inv_orn, tcp_pos, tcp_orn)

    def _sealed(self) -> bool:
        """The cup lip rests on the object's top face, centred enough to seal, and roughly square to it."""
        rel_pos, rel_orn = self._tcp_in_object()
        cup_axis_z = pb.getMatrixFromQuaternion(rel_orn)[8]  # z component of the cup axis (row-major R[2][2])
        margin = self.half - 0.012
        return (
            abs(rel_pos[0]) < margin
            and abs(rel_pos[1]) < margin
            and -self.cfg.seal_distance < rel_pos[2] - self.half < self.cfg.seal_distance
            and cup_axis_z < -0.95
        )

    def _attach(self) -> None:
        # Constraint frame = the TCP frame; the object keeps its pose relative to it at the moment of sealing.
        rel_pos, rel_orn = self._tcp_in_object()
        inv_pos, inv_orn = pb.invertTransform(rel_pos, rel_orn)
        self._create(inv_pos, inv_orn)

    def _create(self, obj_in_tcp_pos, obj_in_tcp_orn) -> None:
        self._cid = pb.createConstraint(
            self.robot,
            self.cup_link,
            self.obj,
            -1,
            pb.JOINT_FIXED,
            (0, 0, 0),
            parentFramePosition=obj_in_tcp_pos,
            childFramePosition=(0, 0, 0),
            parentFrameOrientation=obj_in_tcp_orn,
            childFrameOrientation=(0, 0, 0, 1),
            physicsClientId=self.client,
        )
        pb.setCollisionFilterPair(self.robot, self.obj, self.cup_link, -1, 0, physicsClientId=self.client)
        self.state.attached = True
        self.state.rel_pos, self.state.rel_orn = tuple(obj_in_tcp_pos), tuple(obj_in_tcp_orn)

    def _detach(self) -> None:
        if self._cid is not None:
            pb.removeConstraint(self._cid, physicsClientId=self.client)
            pb.setCollisionFilterPair(self.robot, self.obj, self.cup_link, -1, 1, physicsClientId=self.client)
            self._cid = None
        self.state.attached = False

    def restore(self, state: SuctionState) -> None:
        """Bring the cup to a saved state (after the physics state was restored)."""
        self._detach()
        self.state = SuctionState(**vars(state))
        if state.attached:
            self._create(state.rel_pos, state.rel_orn)

    def snapshot(self) -> SuctionState:
        return SuctionState(**vars(self.state))
