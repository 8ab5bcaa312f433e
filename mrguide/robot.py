"""Robot spec shared by the twin and the deploy stack: URDF, tool frame, limits, home pose, workspace.

The arm is the UR5 of `example-robot-data`; its URDF is resolved from the installed package, never
copied into this repository. A suction cup sits at a fixed offset along the flange (`tool0`) z-axis;
the tool centre point (TCP) is the cup's lip, and the policy always commands it pointing down.
"""

from __future__ import annotations

import importlib.metadata
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mrguide.config import ConfigError
from mrguide.errors import InputError

#: URDF files of the arms we know, relative to the installed example-robot-data package.
KNOWN_ROBOTS: dict[str, str] = {
    "ur5": "cmeel.prefix/share/example-robot-data/robots/ur_description/urdf/ur5_robot.urdf",
}

#: Orientation of the TCP frame in the base frame: z down, x along -y_base (the UR5 home yaw).
R_TOOL_DOWN = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])


class RobotSpecError(InputError):
    """Unknown robot, missing URDF or inconsistent limits."""


@dataclass(frozen=True)
class Workspace:
    """Axis-aligned box in the robot base frame that the normalized action [-1, 1]^3 maps onto (m)."""

    low: tuple[float, float, float] = (0.30, -0.20, 0.045)
    high: tuple[float, float, float] = (0.65, 0.40, 0.35)

    def __post_init__(self) -> None:
        if not np.all(np.asarray(self.high) > np.asarray(self.low)):
            raise ConfigError(f"workspace: high {self.high} must exceed low {self.low} on every axis")

    @property
    def lo(self) -> np.ndarray:
        return np.asarray(self.low, dtype=float)

    @property
    def hi(self) -> np.ndarray:
        return np.asarray(self.high, dtype=float)

    def to_cartesian(self, a: np.ndarray) -> np.ndarray:
        """Map a normalized target in [-1, 1]^3 to a point in the box."""
        return self.lo + (np.asarray(a, dtype=float) + 1.0) * 0.5 * (self.hi - self.lo)

    def to_normalized(self, p: np.ndarray) -> np.ndarray:
        """Inverse of `to_cartesian` (points outside the box map outside [-1, 1])."""
        return 2.0 * (np.asarray(p, dtype=float) - self.lo) / (self.hi - self.lo) - 1.0

    def clamp(self, p: np.ndarray) -> tuple[np.ndarray, bool]:
        """Clamp a point into the box; returns (point, whether it was clamped)."""
        p = np.asarray(p, dtype=float)
        q = np.clip(p, self.lo, self.hi)
        return q, bool(np.any(q != p))

    def contains(self, p: np.ndarray, tol: float = 0.0) -> bool:
        p = np.asarray(p, dtype=float)
        return bool(np.all(p >= self.lo - tol) and np.all(p <= self.hi + tol))


@dataclass(frozen=True)
class RobotConfig:
    """Configurable part of the robot spec ([robot] in a TOML config)."""

    name: str = "ur5"
    #: Suction cup length along the flange z-axis (m): flange to cup lip.
    tool_offset: float = 0.10
    #: Joint limits used by IK, trajectories and safety (rad); tighter than the URDF's ±2π.
    q_lower: tuple[float, ...] = (-2.6, -3.0, -2.8, -3.8, -2.8, -3.2)
    q_upper: tuple[float, ...] = (2.6, -0.1, 2.8, 0.6, -0.3, 3.2)
    #: Joint velocity limits (rad/s), below the UR5 URDF's 3.15/3.2.
    v_max: tuple[float, ...] = (1.5, 1.5, 1.5, 2.0, 2.0, 2.0)
    #: Joint acceleration limits (rad/s^2).
    a_max: tuple[float, ...] = (6.0, 6.0, 6.0, 8.0, 8.0, 8.0)
    #: Joint jerk limits (rad/s^3).
    j_max: tuple[float, ...] = (60.0, 60.0, 60.0, 80.0, 80.0, 80.0)
    #: Home configuration: TCP above the middle of the table, pointing down.
    q_home: tuple[float, ...] = (0.0, -1.5707963, 1.5707963, -1.5707963, -1.5707963, 0.0)
    workspace: Workspace = field(default_factory=Workspace)


@dataclass(frozen=True)
class RobotSpec:
    """Everything about the arm that both the twin and the real robot need."""

    name: str
    urdf_path: Path
    #: Directory that `package://` mesh URIs in the URDF resolve against.
    package_dir: Path
    joint_names: tuple[str, ...]
    base_frame: str
    flange_frame: str
    #: Flange-to-TCP transform (4x4).
    T_flange_tcp: np.ndarray
    q_lower: np.ndarray
    q_upper: np.ndarray
    v_max: np.ndarray
    a_max: np.ndarray
    j_max: np.ndarray
    q_home: np.ndarray
    workspace: Workspace

    @property
    def dof(self) -> int:
        return len(self.joint_names)

    def within_limits(self, q: np.ndarray, tol: float = 1e-9) -> bool:
        q = np.asarray(q, dtype=float)
        return bool(np.all(np.isfinite(q)) and np.all(q >= self.q_lower - tol) and np.all(q <= self.q_upper + tol))


UR5_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)


def resolve_urdf(name: str) -> tuple[Path, Path]:
    """(URDF path, package dir) of a known robot from the installed example-robot-data."""
    if name not in KNOWN_ROBOTS:
        raise RobotSpecError(f"unknown robot {name!r}; known robots: {', '.join(sorted(KNOWN_ROBOTS))}")
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError as exc:
        raise RobotSpecError("package example-robot-data is not installed; `pip install example-robot-data`") from exc
    urdf = Path(str(dist.locate_file(KNOWN_ROBOTS[name])))
    if not urdf.is_file():
        raise RobotSpecError(f"URDF of robot {name!r} not found at {urdf} (example-robot-data {dist.version})")
    package_dir = urdf.parents[4]  # .../share, against which package://example-robot-data/... resolves
    return urdf, package_dir


def load_robot(config: RobotConfig | None = None) -> RobotSpec:
    """Build the robot spec from its config, checking limits for consistency."""
    cfg = config or RobotConfig()
    urdf, package_dir = resolve_urdf(cfg.name)
    arrays = {k: np.asarray(getattr(cfg, k), dtype=float) for k in ("q_lower", "q_upper", "v_max", "a_max", "j_max", "q_home")}
    for key, arr in arrays.items():
        if arr.shape != (len(UR5_JOINTS),) or not np.all(np.isfinite(arr)):
            raise RobotSpecError(f"robot.{key}: expected {len(UR5_JOINTS)} finite values, got {getattr(cfg, key)}")
    if np.any(arrays["q_upper"] <= arrays["q_lower"]):
        raise RobotSpecError("robot: q_upper must exceed q_lower for every joint")
    for key in ("v_max", "a_max", "j_max"):
        if np.any(arrays[key] <= 0):
            raise RobotSpecError(f"robot.{key}: limits must be positive")
    if np.any(arrays["q_home"] < arrays["q_lower"]) or np.any(arrays["q_home"] > arrays["q_upper"]):
        raise RobotSpecError("robot.q_home lies outside the joint limits")
    if cfg.tool_offset < 0:
        raise RobotSpecError("robot.tool_offset must be >= 0")
    T = np.eye(4)
    T[2, 3] = cfg.tool_offset
    return RobotSpec(
        name=cfg.name,
        urdf_path=urdf,
        package_dir=package_dir,
        joint_names=UR5_JOINTS,
        base_frame="base_link",
        flange_frame="tool0",
        T_flange_tcp=T,
        workspace=cfg.workspace,
        **arrays,
    )


def urdf_with_tool(spec: RobotSpec, mesh_root: str, cup_radius: float) -> str:
    """The arm's URDF text with `package://` URIs rooted at `mesh_root` and the suction cup added.

    The cup is a cylinder link `suction_cup` on the flange, as long as the flange-to-TCP offset, and a
    massless `tcp` link sits at its lip. Used by the twin (file paths) and the annotation page (URLs).
    """
    root = ET.fromstring(spec.urdf_path.read_text().replace("package://", mesh_root))
    length = float(spec.T_flange_tcp[2, 3])
    cyl = f'<cylinder radius="{cup_radius}" length="{length}"/>'
    origin = f'<origin xyz="0 0 {length / 2}" rpy="0 0 0"/>'
    root.append(ET.fromstring(
        f'<link name="suction_cup"><inertial><mass value="0.1"/>{origin}'
        f'<inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>'
        f'<visual>{origin}<geometry>{cyl}</geometry><material name="cup"><color rgba="0.15 0.15 0.15 1"/></material></visual>'
        f'<collision>{origin}<geometry>{cyl}</geometry></collision></link>'
    ))
    root.append(ET.fromstring(
        f'<joint name="flange_cup_joint" type="fixed"><parent link="{spec.flange_frame}"/><child link="suction_cup"/>'
        f'<origin xyz="0 0 0" rpy="0 0 0"/></joint>'
    ))
    root.append(ET.fromstring(
        '<link name="tcp"><inertial><mass value="0"/><origin xyz="0 0 0" rpy="0 0 0"/>'
        '<inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial></link>'
    ))
    root.append(ET.fromstring(
        f'<joint name="cup_tcp_joint" type="fixed"><parent link="suction_cup"/><child link="tcp"/>'
        f'<origin xyz="0 0 {length}" rpy="0 0 0"/></joint>'
    ))
    return ET.tostring(root, encoding="unicode")
