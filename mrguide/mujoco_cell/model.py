"""The MuJoCo cell's model, compiled with `mujoco.MjSpec`: the arm from its URDF, the table, the part, the drives
and the suction cup.

- The arm: the same URDF as the twin and Pinocchio (example-robot-data's, or the arm file's), with the cup and
  the `tcp` link added (`robot.urdf_with_tool`; on a spring level-compensator if the cell's cup has a stroke), its STL collision meshes, inertias and effort limits (MuJoCo
  clamps each joint's actuator torque to the URDF's effort). The bodies are gravity-compensated
  (`gravcomp`): the cobot's controller feeds its model's gravity torque forward, as a UR controller does.
- The drives: per joint a position actuator (kp) and a velocity actuator (kv), i.e. a PD position loop with
  velocity feed-forward on the CSP setpoints, tuned as a second-order servo of the configured bandwidth on the
  joint's inertia at home.
- The cup: an adhesion actuator on the cup's body: an attractive force at its contacts, ctrl the vacuum level
  (kPa), gain the cup's area, so that the holding force is F = Δp · A (about 82 N at 65 kPa for a 2 cm lip); and
  the `seal` weld between the cup and the part, inactive until the plant makes it (`seal_weld`).
- Contact, friction and solver: MuJoCo's defaults (pyramidal cones, friction 1, solimp), but contacts as stiff as
  its manual allows at this timestep (`CONTACT_TIMECONST_STEPS`); the integrator is `implicitfast`, MuJoCo's
  recommendation for position actuators with damping.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from mrguide.cell_layout import CUP_RADIUS, TABLE_CENTER, TABLE_HALF_EXTENTS, CupConfig
from mrguide.mujoco_cell.config import MujocoCellConfig
from mrguide.parts import Part
from mrguide.robot import RobotSpec, urdf_with_tool
from mrguide.seal import LIP_COMPLIANCE

#: Pa per kPa: the adhesion gain is the cup's area (m²) times this, its ctrl the vacuum level in kPa.
PA_PER_KPA = 1000.0
#: Where a new part waits until `place_objects` puts it in the cell (upright on the table).
PART_START = (0.5, -0.1)
#: Contacts' time constant, in physics steps: MuJoCo's manual asks for at least 2 (stability); its default of 20 ms
#: (10 steps of its default 2 ms) is a soft contact, which let a held part drift 4.7 mm across the lip during a
#: scripted transport; 4 steps (4 ms at 1 ms) left 0.8 mm (`slip_probe`). A rubber lip on a rigid part deflects
#: well under 1 mm.
CONTACT_TIMECONST_STEPS = 4
#: The cup touches a part with its lip: a ring of this many small spheres of radius LIP_RADIUS on the lip's circle,
#: so that the adhesion pulls all round the lip and the seal resists a moment as a cup does (a rigid cylinder
#: touches a face at one or two points, about which a held part pivots).
LIP_POINTS, LIP_RADIUS = 12, 0.002


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
    lip_geoms: np.ndarray  # the cup's lip ring: what touches a part
    tcp_body: int
    part_body: int
    part_geoms: np.ndarray  # the part's boxes
    part_qpos: int  # the part's free joint: position (3) and quaternion w, x, y, z (4)
    part_dof: int
    cup_body: int
    seal_weld: int  # the weld that holds a sealed part where it sealed (inactive until then)


def _collision_mesh_dir(urdf: str) -> Path:
    """The one directory holding the URDF's collision meshes (MuJoCo reads them by file name from there)."""
    root = ET.fromstring(urdf)
    dirs = {Path(m.get("filename", "")).parent for m in root.findall("./link/collision/geometry/mesh")}
    if len(dirs) != 1:
        raise CellModelError(f"the arm's collision meshes must lie in one directory, found {sorted(map(str, dirs))}")
    return dirs.pop()


def arm_spec(spec: RobotSpec, cfg: MujocoCellConfig, cup: CupConfig) -> mujoco.MjSpec:
    """The arm with its cup from the URDF's collision meshes, gravity-compensated, its level-compensator sprung."""
    urdf = urdf_with_tool(spec, f"{spec.package_dir.as_posix()}/", CUP_RADIUS, cup.stroke)
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
    if cup.stroke > 0:  # the level-compensator: a spring pushing the cup out with `preload` at full extension
        joint = s.joint("flange_cup_joint")
        joint.stiffness = [cup.spring_rate, 0.0, 0.0]  # linear: k, then no quadratic or cubic terms
        joint.springref = cup.preload / cup.spring_rate
    return s


def add_table(s: mujoco.MjSpec) -> None:
    """The table, its top face at z = 0."""
    s.worldbody.add_geom(
        name="table",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=TABLE_HALF_EXTENTS,
        pos=TABLE_CENTER,
        rgba=[0.75, 0.72, 0.66, 1],
    )


def _add_cell(s: mujoco.MjSpec, part: Part, mass: float) -> None:
    """The table and the part, a free body of its boxes (geoms `part0`, `part1`, ...), its `mass` spread over them by
    their volumes."""
    add_table(s)
    body = s.worldbody.add_body(name="part", pos=[*PART_START, 0.5 * part.height])
    body.add_freejoint(name="part_free")
    for i, box in enumerate(part.boxes):
        body.add_geom(
            name=f"part{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=list(box.half),
            pos=list(box.centre),
            mass=mass * box.volume / part.volume,
            rgba=[0.85, 0.1, 0.1, 1],
        )


def _add_lip(s: mujoco.MjSpec, length: float) -> None:
    """The cup's lip: the ring of spheres at the TCP end of the cup (`length` from the flange). Contacts of the lip within
    its compliance (`seal.LIP_COMPLIANCE`) are found but push nothing: there the adhesion pulls a sealed part against the
    lip, as the vacuum does across the lip's compliance."""
    cup = s.body("suction_cup")
    ring = CUP_RADIUS - LIP_RADIUS
    for i in range(LIP_POINTS):
        a = 2.0 * math.pi * i / LIP_POINTS
        cup.add_geom(
            name=f"lip{i}",
            type=mujoco.mjtGeom.mjGEOM_SPHERE,
            size=[LIP_RADIUS, 0.0, 0.0],
            pos=[ring * math.cos(a), ring * math.sin(a), length - LIP_RADIUS],
            margin=LIP_COMPLIANCE,
            gap=LIP_COMPLIANCE,
            mass=0.0,
        )


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


def build_cell(spec: RobotSpec, cfg: MujocoCellConfig, part: Part, cup: CupConfig) -> CellModel:
    """Compile the cell for the arm `spec` with `part` (of the cell's mass, or the library's) and the cup mounted as
    `cup` says (rigid, or on a spring level-compensator)."""
    s = arm_spec(spec, cfg, cup)
    _add_cell(s, part, part.mass if cfg.part_mass is None else cfg.part_mass)
    kp, kv = _servo_gains(s, spec, cfg)
    for name, p, v in zip(spec.joint_names, kp, kv, strict=True):
        pos = s.add_actuator(name=f"{name}_position", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        pos.set_to_position(kp=float(p))
        vel = s.add_actuator(name=f"{name}_velocity", target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        vel.set_to_velocity(kv=float(v))
    adhesion = s.add_actuator(name="cup", target="suction_cup", trntype=mujoco.mjtTrn.mjTRN_BODY)
    adhesion.set_to_adhesion(gain=math.pi * CUP_RADIUS**2 * PA_PER_KPA)
    adhesion.ctrlrange = [0.0, 101.3]
    _add_lip(s, float(spec.T_flange_tcp[2, 3]))
    weld = s.add_equality(name="seal", type=mujoco.mjtEq.mjEQ_WELD, objtype=mujoco.mjtObj.mjOBJ_BODY)
    weld.name1, weld.name2, weld.active = "suction_cup", "part", False
    weld.solref = [CONTACT_TIMECONST_STEPS * cfg.timestep, 1.0]
    model = s.compile()
    part_body = model.body("part")
    lips = np.array([model.geom(f"lip{i}").id for i in range(LIP_POINTS)])
    model.geom_solref[:] = (CONTACT_TIMECONST_STEPS * cfg.timestep, 1.0)  # critically damped, stiff (above)
    for g in range(model.ngeom):  # the cup's cylinder: mass and shape, no contact (the lip touches)
        if model.geom_bodyid[g] == model.body("suction_cup").id and g not in lips:
            model.geom_contype[g] = model.geom_conaffinity[g] = 0
    joints = [model.joint(n) for n in spec.joint_names]
    return CellModel(
        model=model,
        arm_qpos=np.array([j.qposadr[0] for j in joints]),
        arm_dof=np.array([j.dofadr[0] for j in joints]),
        position_actuators=np.array([model.actuator(f"{n}_position").id for n in spec.joint_names]),
        velocity_actuators=np.array([model.actuator(f"{n}_velocity").id for n in spec.joint_names]),
        cup_actuator=model.actuator("cup").id,
        lip_geoms=lips,
        tcp_body=model.body("tcp").id,
        part_body=part_body.id,
        part_geoms=np.array([model.geom(f"part{i}").id for i in range(len(part.boxes))]),
        part_qpos=int(model.joint("part_free").qposadr[0]),
        part_dof=int(model.joint("part_free").dofadr[0]),
        cup_body=model.body("suction_cup").id,
        seal_weld=model.equality("seal").id,
    )
