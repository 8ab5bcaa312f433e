"""The PyBullet cell: table, UR5 with suction cup, one part (`mrguide.parts`), a goal marker, and a camera.

The arm is loaded from example-robot-data's URDF with a cup link (and a `tcp` link at its lip) added
on the fly into a cached copy; the package's own file is never changed or copied into the repo. The
arm follows joint setpoints through PyBullet's position servos, one physics step per control period,
with the reality-gap actuator latency/lag and sensor noise applied on the way.
"""

from __future__ import annotations

import collections
import hashlib
import logging
import os
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as pb

from mrguide.cell_layout import CUP_RADIUS, TABLE_CENTER, TABLE_HALF_EXTENTS
from mrguide.parts import PARTS, Part
from mrguide.robot import RobotSpec, urdf_with_tool
from mrguide.twin.camera import Camera
from mrguide.twin.config import RealityGap, TwinConfig
from mrguide.twin.suction import GRAVITY, SuctionCup, SuctionState

log = logging.getLogger(__name__)


def urdf_with_cup(spec: RobotSpec, stroke: float = 0.0) -> Path:
    """Path of a (content-addressed) URDF = the package's URDF + `suction_cup` and `tcp` links on the flange
    (the cup on a level-compensator of `stroke` m if > 0)."""
    text = urdf_with_tool(spec, f"{spec.package_dir.as_posix()}/", CUP_RADIUS, stroke)
    out = (
        Path(tempfile.gettempdir())
        / "mrguide-urdf"
        / f"{spec.name}-cup-{hashlib.sha1(text.encode()).hexdigest()[:12]}.urdf"
    )
    if not out.exists():
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(text)
        tmp.replace(out)
    return out


def _add_table(client: int) -> int:
    """The table: a static box; its body id."""
    table_col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=TABLE_HALF_EXTENTS, physicsClientId=client)
    table_vis = pb.createVisualShape(
        pb.GEOM_BOX, halfExtents=TABLE_HALF_EXTENTS, rgbaColor=(0.75, 0.72, 0.66, 1), physicsClientId=client
    )
    return pb.createMultiBody(0, table_col, table_vis, TABLE_CENTER, physicsClientId=client)


def _link_and_joint_ids(robot: int, client: int) -> tuple[dict[str, int], dict[str, int]]:
    """The robot's joint indices by child link name, and by joint name."""
    links = {
        pb.getJointInfo(robot, j, physicsClientId=client)[12].decode(): j
        for j in range(pb.getNumJoints(robot, physicsClientId=client))
    }
    joints = {
        pb.getJointInfo(robot, j, physicsClientId=client)[1].decode(): j
        for j in range(pb.getNumJoints(robot, physicsClientId=client))
    }
    return links, joints


def _add_part(client: int, part: Part, gap: RealityGap) -> int:
    """The part from its boxes (one box shape, or a compound of several about its centre of mass: PyBullet's body
    frame), with its mass and friction or the gap's, at its default start; its body id."""
    com = np.asarray(part.centre_of_mass)
    colour = (0.85, 0.1, 0.1, 1)
    if len(part.boxes) == 1:  # a lone box about the origin: Bullet's box shape (a compound of one collides apart)
        half = part.boxes[0].half
        col = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=half, physicsClientId=client)
        vis = pb.createVisualShape(pb.GEOM_BOX, halfExtents=half, rgbaColor=colour, physicsClientId=client)
    else:
        halves = [b.half for b in part.boxes]
        frames = [(np.asarray(b.centre) - com).tolist() for b in part.boxes]
        col = pb.createCollisionShapeArray(
            [pb.GEOM_BOX] * len(halves), halfExtents=halves, collisionFramePositions=frames, physicsClientId=client
        )
        vis = pb.createVisualShapeArray(
            [pb.GEOM_BOX] * len(halves),
            halfExtents=halves,
            visualFramePositions=frames,
            rgbaColors=[colour] * len(halves),
            physicsClientId=client,
        )
    mass = part.mass if gap.object_mass is None else gap.object_mass
    start = (0.5 + com[0], -0.1 + com[1], 0.5 * part.height + com[2])
    body = pb.createMultiBody(mass, col, vis, start, physicsClientId=client)
    pb.changeDynamics(
        body,
        -1,
        lateralFriction=part.friction if gap.object_friction is None else gap.object_friction,
        activationState=pb.ACTIVATION_STATE_DISABLE_SLEEPING,
        physicsClientId=client,
    )
    return body


def _add_goal_marker(client: int) -> int:
    """The goal marker: a visual-only flat green disc at its default place; its body id."""
    goal_vis = pb.createVisualShape(
        pb.GEOM_CYLINDER, radius=0.03, length=0.002, rgbaColor=(0.1, 0.8, 0.2, 0.6), physicsClientId=client
    )
    return pb.createMultiBody(0, -1, goal_vis, (0.5, 0.2, 0.001), physicsClientId=client)


@dataclass
class SceneSnapshot:
    """A restorable state: PyBullet's in-memory state plus what lives outside it."""

    pb_state: int
    suction: SuctionState
    applied: np.ndarray
    pending: list[np.ndarray]
    servo: tuple[np.ndarray, np.ndarray]
    rng_state: Mapping[str, Any]  # the scene RNG's bit-generator state


class Scene:
    """One PyBullet world with the cell in it."""

    def __init__(
        self,
        spec: RobotSpec,
        cfg: TwinConfig,
        part: Part = PARTS["block"],
        seed: int | None = None,
        visuals: bool = False,
    ):
        """Connect to PyBullet (its GUI if `cfg.gui`) and build the cell: arm at home, the part and goal placed.

        The arm's visual meshes are loaded only with `visuals` (or the GUI): parsing them is most of an env's start
        (0.26 s against 0.02 s without: `benchmarks/twin.py`), and only `camera()` draws this world — the cell's HMD and camera render worlds of
        their own (`twin.visual_arm`)."""
        self.spec, self.cfg, self.part = spec, cfg, part
        self.visuals = visuals or cfg.gui
        #: the part's centre of mass in its frame: PyBullet's body frame, which `object_pose` turns into the part's
        self.com = np.asarray(part.centre_of_mass)
        self.client = pb.connect(pb.GUI if cfg.gui else pb.DIRECT)
        c = self.client
        pb.setGravity(*GRAVITY, physicsClientId=c)
        pb.setTimeStep(cfg.control_period, physicsClientId=c)
        pb.setPhysicsEngineParameter(deterministicOverlappingPairs=1, physicsClientId=c)
        self.table = _add_table(c)
        self.robot = pb.loadURDF(
            str(urdf_with_cup(spec, cfg.cup.stroke)),
            useFixedBase=True,
            flags=0 if self.visuals else pb.URDF_IGNORE_VISUAL_SHAPES,
            physicsClientId=c,
        )
        links, joints = _link_and_joint_ids(self.robot, c)
        self.joint_ids = [joints[name] for name in spec.joint_names]
        self.tcp_link = links["tcp"]
        self.cup_link = links["suction_cup"]
        # The level-compensator's spring: the joint's default velocity motor off, a force set every step.
        self._compensator = joints["flange_cup_joint"] if cfg.cup.stroke > 0 else None
        if self._compensator is not None:
            pb.setJointMotorControl2(self.robot, self._compensator, pb.VELOCITY_CONTROL, force=0, physicsClientId=c)
        for link in (-1, 0, 1):  # the arm is bolted to the table: no contacts between its base and the top
            pb.setCollisionFilterPair(self.table, self.robot, -1, link, 0, physicsClientId=c)
        efforts = [pb.getJointInfo(self.robot, j, physicsClientId=c)[10] for j in self.joint_ids]
        self._motor_args = {  # the servo call's constant arguments, built once (it runs every 4 ms period)
            "forces": efforts,
            "positionGains": [0.6] * spec.dof,
            "velocityGains": [1.0] * spec.dof,
        }
        h = 0.5 * part.height
        gap = cfg.reality_gap
        self.object = _add_part(c, part, gap)
        self.goal_marker = _add_goal_marker(c)
        self.suction = SuctionCup(c, self.robot, self.tcp_link, self.object, part, cfg.vacuum, cfg.control_period)
        self.suction.break_force = gap.suction_break_force
        self.rng = np.random.default_rng(seed)
        self._applied = spec.q_home.copy()
        self._pending: collections.deque[np.ndarray] = collections.deque()
        self.goal = np.array([0.5, 0.2, h])
        self._last_servo = (spec.q_home.copy(), np.zeros(spec.dof))
        self._initial_state: int | None = None
        self.place(spec.q_home, np.array([0.5, -0.1, h]), self.goal)
        self._initial_state = pb.saveState(physicsClientId=c)

    # -- set-up ----------------------------------------------------------------------------------
    def place(self, q: np.ndarray, obj: np.ndarray, goal: np.ndarray) -> None:
        """Arm at rest at q, object at rest at `obj` (upright), goal marker at `goal`, vacuum off."""
        c = self.client
        if self._initial_state is not None:
            self.suction.set_vacuum(False)
            pb.restoreState(self._initial_state, physicsClientId=c)
        self.suction.restore(SuctionState())
        for j, qj in zip(self.joint_ids, q):
            pb.resetJointState(self.robot, j, float(qj), 0.0, physicsClientId=c)
        if self._compensator is not None:
            pb.resetJointState(self.robot, self._compensator, 0.0, 0.0, physicsClientId=c)
        self._servo(np.asarray(q, float), np.zeros(self.spec.dof))
        self._applied = np.asarray(q, float).copy()
        self._pending.clear()
        self.place_objects(obj, goal)

    def place_objects(self, obj: np.ndarray, goal: np.ndarray) -> None:
        """Object at rest at `obj` (upright, released), goal marker at `goal`; the arm is left as it is."""
        c = self.client
        self.suction.set_vacuum(False)
        # Park the object far away for one collision pass: this empties the contact manifolds that
        # restoreState leaves behind, so a seeded episode does not depend on the previous one.
        pb.resetBasePositionAndOrientation(self.object, (0, 0, -10), (0, 0, 0, 1), physicsClientId=c)
        pb.performCollisionDetection(physicsClientId=c)
        pb.resetBasePositionAndOrientation(self.object, (obj + self.com).tolist(), (0, 0, 0, 1), physicsClientId=c)
        pb.resetBaseVelocity(self.object, (0, 0, 0), (0, 0, 0), physicsClientId=c)
        pb.resetBasePositionAndOrientation(self.goal_marker, (goal[0], goal[1], 0.001), (0, 0, 0, 1), physicsClientId=c)
        self.goal = np.asarray(goal, float).copy()

    def reseed(self, seed: int | None) -> None:
        self.rng = np.random.default_rng(seed)

    # -- actuation -------------------------------------------------------------------------------
    def command(self, q: np.ndarray, dq: np.ndarray) -> None:
        """Send one control-period joint setpoint to the servos, through the latency/lag of the gap."""
        gap = self.cfg.reality_gap
        self._pending.append(np.asarray(q, float))
        if len(self._pending) <= gap.actuator_latency:
            return
        q_cmd = self._pending.popleft()
        if gap.actuator_lag > 0:
            k = 1.0 - np.exp(-self.cfg.control_period / gap.actuator_lag)
            q_cmd = self._applied + k * (q_cmd - self._applied)
            dq = (q_cmd - self._applied) / self.cfg.control_period
        self._applied = q_cmd
        self._servo(q_cmd, dq)

    def _servo(self, q: np.ndarray, dq: np.ndarray) -> None:
        self._last_servo = (q, dq)
        pb.setJointMotorControlArray(
            self.robot,
            self.joint_ids,
            pb.POSITION_CONTROL,
            targetPositions=q.tolist(),
            targetVelocities=np.asarray(dq).tolist(),
            physicsClientId=self.client,
            **self._motor_args,
        )

    def set_vacuum(self, on: bool) -> None:
        self.suction.set_vacuum(on)

    def step(self) -> None:
        """Advance one control period."""
        if self._compensator is not None:
            cup = self.cfg.cup
            pb.setJointMotorControl2(
                self.robot,
                self._compensator,
                pb.TORQUE_CONTROL,
                force=cup.preload + cup.spring_rate * self.cup_compression(),
                physicsClientId=self.client,
            )
        pb.stepSimulation(physicsClientId=self.client)
        self.suction.update()

    # -- sensing ---------------------------------------------------------------------------------
    def joint_positions(self, noisy: bool = True) -> np.ndarray:
        states = pb.getJointStates(self.robot, self.joint_ids, physicsClientId=self.client)
        q = np.array([s[0] for s in states])
        sigma = self.cfg.reality_gap.joint_noise
        return q + self.rng.normal(0.0, sigma, q.shape) if noisy and sigma > 0 else q

    def joint_velocities(self) -> np.ndarray:
        return np.array([s[1] for s in pb.getJointStates(self.robot, self.joint_ids, physicsClientId=self.client)])

    def cup_compression(self) -> float:
        """How far the cup has retracted on its level-compensator (m, 0 = fully extended; 0 for a rigid cup)."""
        if self._compensator is None:
            return 0.0
        return -float(pb.getJointState(self.robot, self._compensator, physicsClientId=self.client)[0])

    def vacuum_level(self) -> float:
        """Vacuum level reading (kPa gauge, negative below atmosphere)."""
        sigma = self.cfg.reality_gap.vacuum_noise
        return self.suction.state.level + (float(self.rng.normal(0.0, sigma)) if sigma > 0 else 0.0)

    def object_position(self) -> np.ndarray:
        """The part's origin (m, base frame)."""
        return self.object_pose()[0]

    def object_pose(self) -> tuple[np.ndarray, np.ndarray]:
        """The part's origin (m) and its quaternion (x, y, z, w), base frame."""
        pos, orn = pb.getBasePositionAndOrientation(self.object, physicsClientId=self.client)
        rot = np.array(pb.getMatrixFromQuaternion(orn)).reshape(3, 3)
        return np.array(pos) - rot @ self.com, np.array(orn)

    def tcp_pose_pybullet(self) -> tuple[np.ndarray, np.ndarray]:
        """TCP position and quaternion (x, y, z, w) as PyBullet computes them (for cross-checks)."""
        pos, orn = pb.getLinkState(
            self.robot, self.tcp_link, computeForwardKinematics=True, physicsClientId=self.client
        )[4:6]
        return np.array(pos), np.array(orn)

    def camera(self) -> Camera:
        """The twin's camera on this world; the arm must have been loaded with its visual meshes."""
        if not self.visuals:
            raise RuntimeError("this twin scene was built without the arm's visual meshes: Scene(..., visuals=True)")
        return Camera.from_config(self.client, self.cfg.camera)

    # -- save / restore --------------------------------------------------------------------------
    def snapshot(self) -> SceneSnapshot:
        """Capture the whole scene; release it with `discard` when no longer needed."""
        return SceneSnapshot(
            pb.saveState(physicsClientId=self.client),
            self.suction.snapshot(),
            self._applied.copy(),
            [p.copy() for p in self._pending],
            (self._last_servo[0].copy(), np.asarray(self._last_servo[1]).copy()),
            self.rng.bit_generator.state,
        )

    def restore(self, snap: SceneSnapshot) -> None:
        self.suction.set_vacuum(False)
        pb.restoreState(snap.pb_state, physicsClientId=self.client)
        self.suction.restore(snap.suction)
        self._applied = snap.applied.copy()
        self._pending = collections.deque(p.copy() for p in snap.pending)
        self._servo(snap.servo[0].copy(), snap.servo[1].copy())
        self.rng.bit_generator.state = snap.rng_state

    def discard(self, snap: SceneSnapshot) -> None:
        pb.removeState(snap.pb_state, physicsClientId=self.client)

    def close(self) -> None:
        if pb.isConnected(self.client):
            pb.disconnect(self.client)
