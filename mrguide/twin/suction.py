"""Vacuum gripper of the twin: a fixed constraint made on a seal, broken by force, plus a vacuum signal.

As in google-research/ravens, suction is a fixed constraint between the cup and the object, removed on release.
Unlike ravens, the seal is the cell's (`mrguide.seal`, the same as the MuJoCo cup's): with the vacuum on and the
lip resting on a face of the object, the generator reaches the level the lip's leak past the face's edge leaves,
and the constraint is made only where that level passes the part-present threshold. The generator reports its
level with a first-order lag, from which the part-present signal is derived as on a real unit.

The constraint breaks when the load on the cup exceeds what the level holds (`seal.holds`: Δp · A off the face,
friction along it), or, in a cell with a reality gap, the gap's break force. The load is what the part's weight and
its acceleration ask of the cup, m (a − g), while the part hangs from the arm alone; while it touches anything else
(the table) that carries it. Not the constraint's own force: while the rigid arm squeezes the part against the
table, that carries tens of newtons of the contact solver's fight between the two (pulls of up to 70 N in the
scripted expert's grasps, where nothing pulls; m (a − g) stays within 6 N).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pybullet as pb

from mrguide import seal
from mrguide.parts import Part
from mrguide.twin.config import VacuumConfig

#: m/s², the twin's gravity (the scene sets it).
GRAVITY = (0.0, 0.0, -9.81)


def _axis(orn: tuple[float, ...]) -> np.ndarray:
    """The third axis of the frame of quaternion `orn` (x, y, z, w): the cup's axis, out of the lip."""
    m = pb.getMatrixFromQuaternion(orn)  # row-major: the axis is the third column
    return np.array((m[2], m[5], m[8]))


@dataclass
class SuctionState:
    """Everything needed to restore the cup: vacuum command, level, and the attachment (if any)."""

    vacuum_on: bool = False
    level: float = 0.0
    attached: bool = False
    rel_pos: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rel_orn: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)
    breaks: int = 0
    #: kPa below atmosphere the generator reaches with the cup where it is (with the part: where it sealed)
    reach: float = 0.0
    #: the sealed face's outward normal in the object's frame
    normal: tuple[float, float, float] = (0.0, 0.0, 1.0)
    #: the object's velocity at the last period (m/s, world): its acceleration is the load's
    velocity: tuple[float, float, float] = (0.0, 0.0, 0.0)


class SuctionCup:
    """The vacuum cup on link `cup_link` of `robot`, gripping the body `obj` of `part` (PyBullet's body frame at the
    part's centre of mass)."""

    def __init__(self, client: int, robot: int, cup_link: int, obj: int, part: Part, cfg: VacuumConfig, dt: float):
        self.client, self.robot, self.cup_link, self.obj = client, robot, cup_link, obj
        self.boxes = part.boxes
        self.com = np.asarray(part.centre_of_mass)
        self.mass = float(pb.getDynamicsInfo(obj, -1, physicsClientId=client)[0])
        self.cfg = cfg
        self.dt = dt
        self._level_gain = 1.0 - math.exp(-dt / cfg.time_constant)  # first-order lag over one period
        #: N: the cup lets go above this load whatever its level holds (a reality gap's weaker cup)
        self.break_force = math.inf
        self.leak = 0.0  # fault injection: fraction of the sealed vacuum lost through a leak
        #: Called at each break with the load on the cup (N, in the part's frame; along the sealed face's normal < 0
        #: pulls the part off) and the cup's pose in the part's frame (position, m): for probes (tools/break_probe.py).
        self.on_break: Callable[[tuple[float, ...], tuple[float, ...]], None] | None = None
        self.state = SuctionState()
        self._cid: int | None = None
        self._cup_body = int(pb.getJointInfo(robot, cup_link, physicsClientId=client)[16])  # the lip link's parent

    def set_vacuum(self, on: bool) -> None:
        """Vacuum on (grip) or off (release: the constraint goes at once)."""
        self.state.vacuum_on = bool(on)
        if not on:
            self._detach()

    def part_present(self, level: float | None = None) -> bool:
        """The generator's part-gripped signal: level below the threshold."""
        return (self.state.level if level is None else level) < self.cfg.part_threshold

    def update(self) -> None:
        """One physics period: seal if the level reached holds the part, break if overloaded, advance the level."""
        s = self.state
        if s.vacuum_on and not s.attached:
            s.reach = self._level_reached()
            if -s.reach < self.cfg.part_threshold:
                self._attach()
        elif s.attached:
            self._check_hold()
        target = -s.reach * (1.0 - self.leak) if s.vacuum_on else 0.0
        s.level += (target - s.level) * self._level_gain
        if s.attached and target > self.cfg.part_threshold and s.level > self.cfg.part_threshold:
            self._detach()  # a leak let the vacuum decay below what holds the part: it falls

    def _check_hold(self) -> None:
        """Let the part go if its load exceeds what the cup holds while nothing else carries it."""
        s = self.state
        velocity = pb.getBaseVelocity(self.obj, physicsClientId=self.client)[0]
        accel = [(v - u) / self.dt for v, u in zip(velocity, s.velocity, strict=True)]
        s.velocity = (velocity[0], velocity[1], velocity[2])
        orn = pb.getBasePositionAndOrientation(self.obj, physicsClientId=self.client)[1]
        rot = pb.getMatrixFromQuaternion(orn)  # row-major; the load on the cup, −m (a − g), into the object's frame
        world = [-self.mass * (a - g) for a, g in zip(accel, GRAVITY, strict=True)]
        load = [sum(rot[3 * i + k] * world[i] for i in range(3)) for k in range(3)]
        pull = -sum(f * n for f, n in zip(load, s.normal, strict=True))
        shear = math.sqrt(max(sum(f * f for f in load) - pull * pull, 0.0))
        if (math.hypot(pull, shear) <= self.break_force and seal.holds(pull, shear, -s.level)) or self._supported():
            return
        s.breaks += 1
        if self.on_break is not None:
            self.on_break((load[0], load[1], load[2]), tuple(self._tcp_in_object()[0]))
        self._detach()

    def _supported(self) -> bool:
        """The object touches something besides the arm and its cup (the table), which carries it."""
        contacts = pb.getContactPoints(bodyA=self.obj, physicsClientId=self.client)
        return any(c[2] != self.robot for c in contacts)

    def _tcp_in_object(self) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """Cup pose in the body's frame (position, quaternion x y z w); called every period while the vacuum is on."""
        tcp_pos, tcp_orn = pb.getLinkState(
            self.robot, self.cup_link, computeForwardKinematics=True, physicsClientId=self.client
        )[4:6]
        obj_pos, obj_orn = pb.getBasePositionAndOrientation(self.obj, physicsClientId=self.client)
        inv_pos, inv_orn = pb.invertTransform(obj_pos, obj_orn)
        return pb.multiplyTransforms(inv_pos, inv_orn, tcp_pos, tcp_orn)

    def _lip(self) -> tuple[np.ndarray, np.ndarray]:
        """The lip's centre and the cup's axis (out of the lip) in the part's frame."""
        rel_pos, rel_orn = self._tcp_in_object()
        return np.array(rel_pos) + self.com, _axis(rel_orn)

    def _level_reached(self) -> float:
        """kPa below atmosphere the generator reaches with the cup where it is (`seal.level_reached`)."""
        rel, axis = self._lip()
        return seal.level_reached(rel, axis, self.boxes, -self.cfg.level_sealed, -self.cfg.level_open)

    def _attach(self) -> None:
        # Constraint frame = the TCP frame; the object keeps its pose relative to it at the moment of sealing.
        rel_pos, rel_orn = self._tcp_in_object()
        nx, ny, nz = seal.face_normal(_axis(rel_orn))
        self.state.normal = (float(nx), float(ny), float(nz))
        vx, vy, vz = pb.getBaseVelocity(self.obj, physicsClientId=self.client)[0]
        self.state.velocity = (vx, vy, vz)
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
        self._collide(False)
        self.state.attached = True
        self.state.rel_pos, self.state.rel_orn = tuple(obj_in_tcp_pos), tuple(obj_in_tcp_orn)

    def _collide(self, on: bool) -> None:
        """Contacts between the object and the cup (its lip link and the cup's body) on or off: a held object is
        held by the constraint alone, so that no contact of the two outlives a snapshot (PyBullet's saved state has
        no contact manifolds) and a restored episode replays exactly."""
        for link in (self.cup_link, self._cup_body):
            pb.setCollisionFilterPair(self.robot, self.obj, link, -1, int(on), physicsClientId=self.client)

    def _detach(self) -> None:
        if self._cid is not None:
            pb.removeConstraint(self._cid, physicsClientId=self.client)
            self._collide(True)
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
