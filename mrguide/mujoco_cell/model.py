"""The MuJoCo cell's model, compiled with `mujoco.MjSpec`: the arm from its URDF, the table, the part, the drives
and the suction cup.

- The arm: the same URDF as the twin and Pinocchio (example-robot-data's, or the arm file's), with the cup and
  the `tcp` link added (`robot.urdf_with_tool`), its STL collision meshes, inertias and effort limits (MuJoCo
  clamps each joint's actuator torque to the URDF's effort). The bodies are gravity-compensated
  (`gravcomp`): the cobot's controller feeds its model's gravity torque forward, as a UR controller does.
- The drives: per joint a position actuator (kp) and a velocity actuator (kv), i.e. a PD position loop with
  velocity feed-forward on the CSP setpoints, tuned as a second-order servo of the configured bandwidth on the
  joint's inertia at home.
- The cup: an adhesion actuator on the cup's body: an attractive force at its contacts, ctrl the vacuum level
  (kPa), gain the cup's area, so that the holding force is F = Δp · A (about 82 N at 65 kPa for a 2 cm lip).
- Contact, friction and solver: MuJoCo's defaults (elliptic cones are not needed: pyramidal, friction 1).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from mrguide.cell_layout import CUP_RADIUS, TABLE_CENTER, TABLE_HALF_EXTENTS
from mrguide.mujoco_cell.config import MujocoCellConfig
from mrguide.robot import RobotSpec, urdf_with_tool

#: Pa per kPa: the adhesion gain is the cup's area (m²) times this, its ctrl the vacuum level in kPa.
PA_PER_KPA = 1000.0
#: Where a new part waits until `place_objects` puts it in the cell (upright on the table).
PART_START = (0.5, -0.1)


class CellModelError(RuntimeError):
    """The arm's URDF cannot be compiled into the MuJoCo cell (e.g. its collision meshes are not STL/OBJ)."""


@dataclass(frozen=True)
class CellModel:
    """The compiled model and the addresses the plant reads and writes."""

    model: mujoco.MjModel
    arm_qpos: np.ndarray  # qpos address of each arm joint, robot order
    arm_dof: np.ndarray  # dof address of each arm joint
    position_actuators: np.ndarray
    velocity_actuators: np.ndarray
    cup_actuator: int
    cup_geom: int
    tcp_body: int
    part_body: int
    part_geom: int
    part_qpos: int  # the part's free joint: position (3) and quaternion w, x, y, z (4)
    part_dof: int


def _collision_mesh_dir(urdf: str) -> Path:
    """The one directory holding the URDF's collision meshes (MuJoCo reads them by file name from there)."""
    root = ET.fromstring(urdf)
    dirs = {Path(m.get("filename", "")).parent for m in root.findall("./link/collision/geometry/mesh")}
    if len(dirs) != 1:
        raise CellModelError(f"the arm's collision meshes must lie in one directory, found {sorted(map(str, dirs))}")
    return dirs.pop()


def _arm_spec(spec: RobotSpec, cfg: MujocoCellConfig) -> mujoco.MjSpec:
    urdf = urdf_with_tool(spec, f"{spec.package_dir.as_posix()}/", CUP_RADIUS)
    root = ET.fromstring(urdf)
    ext = ET.SubElement(root, "mujoco")
    ET.SubElement(
        ext,
        "compiler",
        meshdir=str(_collision_mesh_dir(urdf)),
        discardvisual="true",
        fusestatic="false",
        strippath="true",
    )
    try:
        s = mujoco.MjSpec.from_string(ET.tostring(root, encoding="unicode"))
    except ValueError as exc:
        raise CellModelError(f"MuJoCo cannot read the arm's URDF {spec.urdf_path}: {exc}") from exc
    s.option.timestep = cfg.timestep
    s.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    for body in s.bodies:
        if body.name != "world":
            body.gravcomp = 1.0
    return s


def _add_cell(s: mujoco.MjSpec, part_size: float, part_mass: float) -> None:
    """The table (top face at z = 0) and the part, a free cube."""
    s.worldbody.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=TABLE_HALF_EXTENTS,
        pos=TABLE_CENTER,
        rgba=[0.75, 0.72, 0.66, 1],
    )
    h = 0.5 * part_size
    part = s.worldbody.add_body(name="part", pos=[*PART_START, h])
    part.add_freejoint(name="part_free")
    part.add_geom(name="part", type=mujoco.mjtGeom.mjGEOM_BOX, size=[h, h, h], mass=part_mass, rgba=[0.85, 0.1, 0.1, 1])


def _servo_gains(s: mujoco.MjSpec, spec: RobotSpec, cfg: MujocoCellConfig) -> tuple[np.ndarray, np.ndarray]:
    """(kp, kv) per joint: a second-order loop of the configured bandwidth and damping on the joint's inertia at
    home (the diagonal of the mass matrix there)."""
    model = s.compile()
    data = mujoco.MjData(model)
    adr = [model.joint(name).qposadr[0] for name in spec.joint_names]
    data.qpos[adr] = spec.q_home
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    inertia = np.array([full[model.joint(n).dofadr[0], model.joint(n).dofadr[0]] for n in spec.joint_names])
    omega = 2.0 * math.pi * cfg.servo_bandwidth_hz
    return inertia * omega**2, 2.0 * cfg.servo_damping_ratio * inertia * omega


def build_cell(spec: RobotSpec, cfg: MujocoCellConfig, part_size: float) -> CellModel:
    """Compile the cell for the arm `spec` with a cube part of edge `part_size` (m)."""
    s = _arm_spec(spec, cfg)
    _add_cell(s, part_size, cfg.part_mass)
    kp, kv = _servo_gains(s, spec, cfg)
    for name, p, v in zip(spec.joint_names, kp, kv, strict=True):
        pos = s.add_actuator(name=f"{name}_position", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        pos.set_to_position(kp=float(p))
        vel = s.add_actuator(name=f"{name}_velocity", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        vel.set_to_velocity(kv=float(v))
    cup = s.add_actuator(name="cup", target="suction_cup", trntype=mujoco.mjtTrn.mjTRN_BODY)
    cup.set_to_adhesion(gain=math.pi * CUP_RADIUS**2 * PA_PER_KPA)
    cup.ctrlrange = [0.0, 101.3]
    model = s.compile()
    part = model.body("part")
    cup_geoms = [g for g in range(model.ngeom) if model.geom_bodyid[g] == model.body("suction_cup").id]
    if len(cup_geoms) != 1:
        raise CellModelError(f"the cup link should have one collision geom, it has {len(cup_geoms)}")
    # contacts of the cup within `seal_gap` are found but push nothing: there the adhesion pulls a sealed part up
    # against the lip, as the vacuum does across the lip's compliance
    model.geom_margin[cup_geoms[0]] = model.geom_gap[cup_geoms[0]] = cfg.seal_gap
    joints = [model.joint(n) for n in spec.joint_names]
    return CellModel(
        model=model,
        arm_qpos=np.array([j.qposadr[0] for j in joints]),
        arm_dof=np.array([j.dofadr[0] for j in joints]),
        position_actuators=np.array([model.actuator(f"{n}_position").id for n in spec.joint_names]),
        velocity_actuators=np.array([model.actuator(f"{n}_velocity").id for n in spec.joint_names]),
        cup_actuator=model.actuator("cup").id,
        cup_geom=cup_geoms[0],
        tcp_body=model.body("tcp").id,
        part_body=part.id,
        part_geom=model.geom("part").id,
        part_qpos=int(model.joint("part_free").qposadr[0]),
        part_dof=int(model.joint("part_free").dofadr[0]),
    )
